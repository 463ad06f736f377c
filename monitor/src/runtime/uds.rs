//! The runtime as a UDS DTC server: [`UdsServer`] answers ReadDTCInformation (0x19) and
//! ClearDiagnosticInformation (0x14) requests from the runtime's event memories through
//! [`fdd_diagnostics::uds::handle_request`].
//!
//! DIDs of snapshot values are one table for the whole runtime (ISO 14229-1: a DID means the
//! same data everywhere in an ECU): every distinct freeze-frame item name of every monitor, in
//! monitor order then event order, gets `0xFD00`, `0xFD01`, ... ([`Runtime::snapshot_dids`]).

use fdd_diagnostics::dtc::{Dtc, DtcGroup, DtcStatus};
use fdd_diagnostics::uds::{
    memory_extended_data, memory_snapshot, ClearRefused, DtcStore, ExtendedData, SnapshotValue,
};

use super::{Runtime, RuntimeError, Sink};

/// First DID of the runtime's snapshot values (ISO 14229-1 system-supplier range).
pub const SNAPSHOT_DID_BASE: u16 = 0xFD00;

impl Runtime {
    /// The DID of each freeze-frame item in snapshot records: `(did, item name)`.
    pub fn snapshot_dids(&self) -> Vec<(u16, String)> {
        let mut names: Vec<String> = Vec::new();
        for (_, ev) in self.event_memories() {
            let mem = ev.memory();
            for id in mem.event_ids() {
                for s in mem.freeze_frame_signals(id) {
                    if !names.contains(s) {
                        names.push(s.clone());
                    }
                }
            }
        }
        names
            .into_iter()
            .enumerate()
            .map(|(k, n)| (SNAPSHOT_DID_BASE.saturating_add(k as u16), n))
            .collect()
    }
}

/// A UDS DTC server over a runtime: clears are stamped with the runtime's current time and
/// their events go to `sink`.
pub struct UdsServer<'r> {
    rt: &'r mut Runtime,
    sink: &'r mut dyn Sink,
    dids: Vec<(u16, String)>,
}

impl<'r> UdsServer<'r> {
    /// A server answering from `rt` (builds the DID table once).
    pub fn new(rt: &'r mut Runtime, sink: &'r mut dyn Sink) -> Self {
        let dids = rt.snapshot_dids();
        UdsServer { rt, sink, dids }
    }

    /// Answers one request into `response` (see [`fdd_diagnostics::uds::handle_request`]).
    pub fn handle(
        &mut self,
        request: &[u8],
        response: &mut Vec<u8>,
    ) -> fdd_diagnostics::uds::Reply {
        fdd_diagnostics::uds::handle_request(self, request, response)
    }
}

impl DtcStore for UdsServer<'_> {
    fn status_availability_mask(&self) -> u8 {
        self.rt.status_availability_mask()
    }

    fn for_each_dtc(&self, f: &mut dyn FnMut(Dtc, DtcStatus)) {
        for (d, s) in self.rt.dtcs() {
            f(d, s);
        }
    }

    fn snapshot(&self, dtc: Dtc, visit: &mut dyn FnMut(SnapshotValue)) -> Option<DtcStatus> {
        let did_of = |name: &str| self.dids.iter().find(|(_, n)| n == name).map(|(d, _)| *d);
        self.rt
            .event_memories()
            .find_map(|(_, ev)| memory_snapshot(ev.memory(), dtc, &did_of, visit))
    }

    fn extended_data(&self, dtc: Dtc) -> Option<ExtendedData> {
        self.rt
            .event_memories()
            .find_map(|(_, ev)| memory_extended_data(ev.memory(), dtc))
    }

    fn clear(&mut self, group: DtcGroup) -> Result<usize, ClearRefused> {
        let t = self.rt.now_ns().unwrap_or(0);
        match self.rt.clear_dtc(group, t, self.sink) {
            Ok(n) => Ok(n),
            Err(RuntimeError::UnknownDtc(d)) => Err(ClearRefused::UnknownDtc(d)),
            Err(_) => Err(ClearRefused::ConditionsNotCorrect(
                "the event memory refused the clear",
            )),
        }
    }
}
