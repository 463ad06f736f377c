//! The DTC side of a subsystem monitor: its own event memory, one event per DTC, qualified by
//! the monitor itself (`MonitorInternal` debounce: the monitor's persistence and decision logic
//! is the debounce), reported every step with one verdict per event, and the status bytes
//! forwarded as [`Output::DtcStatus`] when they change.
//!
//! Sized at construction; a step without a status change allocates nothing.

use fdd_diagnostics::dtc::{
    DebounceConfig, Dtc, EventConfig, EventId, EventMemory, EventMemoryConfig, MemoryImage,
    MilConfig, ReportContext, RestoreReport,
};
use fdd_diagnostics::event::DiagnosticEvent;
use fdd_diagnostics::{ConfigError, TestResult, Verdict};

use crate::monitor::{Output, OutputSink};

/// One event of a monitor: its name, its DTC (`P0106-64`) and its memory priority (1 highest).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EventSpec<'a> {
    pub name: &'a str,
    pub dtc: &'a str,
    pub priority: u8,
}

/// A monitor's event memory and the last status byte reported per event.
#[derive(Debug)]
pub struct MonitorEvents {
    memory: EventMemory,
    ids: Vec<EventId>,
    statuses: Vec<u8>,
}

impl MonitorEvents {
    /// Memory entries (stored DTCs) a monitor keeps.
    pub const CAPACITY: usize = 8;

    /// Builds the memory: confirmation after 2 failed operation cycles, aging after 40, the
    /// default MIL policy, no freeze frame. Errors name the offending event key.
    pub fn new(specs: &[EventSpec<'_>]) -> Result<Self, ConfigError> {
        let events = specs
            .iter()
            .map(|s| EventConfig {
                name: s.name.to_string(),
                dtc: s.dtc.to_string(),
                priority: s.priority,
                debounce: DebounceConfig::MonitorInternal,
                confirmation_threshold: 2,
                aging_threshold: 40,
                mil: MilConfig::default(),
                freeze_frame: Vec::new(),
                freeze_frame_update: Default::default(),
            })
            .collect();
        let memory = EventMemory::new(&EventMemoryConfig {
            capacity: Self::CAPACITY,
            events,
        })?;
        let ids = (0..specs.len())
            .map(|i| {
                memory
                    .event_id_at(i)
                    .ok_or_else(|| ConfigError::new("events", i, "event missing from the memory"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            statuses: vec![0x50; ids.len()],
            memory,
            ids,
        })
    }

    /// Number of events.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// True without events.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// The DTC of event `i`.
    pub fn dtc(&self, i: usize) -> Dtc {
        self.memory.dtc(self.ids[i])
    }

    /// Reports one verdict per event at `now_s`. A failed event carries `failed` (the test
    /// result that qualified the fault) and the isolation `candidates`; the others carry only
    /// their verdict. Status changes go out as events and status bytes.
    pub fn report(
        &mut self,
        now_s: f64,
        verdicts: &[Verdict],
        failed: &TestResult,
        candidates: &[(&str, f64)],
        out: &mut OutputSink<'_>,
    ) {
        for (i, &verdict) in verdicts.iter().enumerate().take(self.ids.len()) {
            let result = if verdict == Verdict::Failed {
                *failed
            } else {
                TestResult {
                    value: 0.0,
                    min: 0.0,
                    max: 0.0,
                    verdict,
                }
            };
            let ctx = if verdict == Verdict::Failed && !candidates.is_empty() {
                ReportContext::at(now_s).with_candidates(candidates)
            } else {
                ReportContext::at(now_s)
            };
            let mut sink = |e: DiagnosticEvent| out(Output::Event(&e));
            if let Ok(status) = self.memory.report(self.ids[i], &result, &ctx, &mut sink) {
                if status.byte() != self.statuses[i] {
                    self.statuses[i] = status.byte();
                    out(Output::DtcStatus {
                        dtc: self.memory.dtc(self.ids[i]),
                        status,
                    });
                }
            }
        }
    }

    /// The event memory, read-only (for persistence: [`EventMemory::encode_image`]).
    pub fn memory(&self) -> &EventMemory {
        &self.memory
    }

    /// Restores a persisted image at power-up, before the first operation cycle (see
    /// [`EventMemory::restore`]). The restored status bytes become the last reported ones, so
    /// the next step reports only what changes from them; a host that wants the restored
    /// statuses published reads them from [`MonitorEvents::memory`].
    pub fn restore(&mut self, image: &MemoryImage) -> RestoreReport {
        let report = self.memory.restore(image);
        for (s, &id) in self.statuses.iter_mut().zip(&self.ids) {
            *s = self.memory.status(id).byte();
        }
        report
    }

    /// An operation cycle starts.
    pub fn start_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        let mut sink = |e: DiagnosticEvent| out(Output::Event(&e));
        let _ = self
            .memory
            .start_operation_cycle(now_ns as f64 * 1e-9, &mut sink);
    }

    /// The operation cycle ends.
    pub fn end_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        let mut sink = |e: DiagnosticEvent| out(Output::Event(&e));
        let _ = self
            .memory
            .end_operation_cycle(now_ns as f64 * 1e-9, &mut sink);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fdd_diagnostics::dtc::StatusBit;

    fn specs() -> [EventSpec<'static>; 2] {
        [
            EventSpec {
                name: "a",
                dtc: "P0106-64",
                priority: 2,
            },
            EventSpec {
                name: "b",
                dtc: "P0401-00",
                priority: 3,
            },
        ]
    }

    #[test]
    fn a_failed_verdict_raises_its_dtc_with_the_result_and_candidates() {
        let mut ev = MonitorEvents::new(&specs()).expect("valid");
        assert_eq!(ev.len(), 2);
        assert_eq!(ev.dtc(1).to_string(), "P0401-00");
        let mut events = Vec::new();
        let mut statuses = Vec::new();
        let mut out = |o: Output<'_>| match o {
            Output::Event(e) => events.push(e.clone()),
            Output::DtcStatus { dtc, status } => statuses.push((dtc.to_string(), status.byte())),
            _ => {}
        };
        ev.start_operation_cycle(0, &mut out);
        let failed = TestResult {
            value: 9.0,
            min: 0.0,
            max: 5.0,
            verdict: Verdict::Failed,
        };
        ev.report(
            1.0,
            &[Verdict::Failed, Verdict::Passed],
            &failed,
            &[("map_sensor", 0.9), ("leak", 0.1)],
            &mut out,
        );
        let raised: Vec<_> = events
            .iter()
            .filter(|e| e.bit_changed(StatusBit::TestFailed) && e.status_after.test_failed())
            .collect();
        assert_eq!(raised.len(), 1);
        assert_eq!(raised[0].event, "a");
        assert_eq!(raised[0].test_result.map(|r| r.value), Some(9.0));
        assert_eq!(raised[0].candidates[0].fault, "map_sensor");
        assert!(statuses.iter().any(|(d, s)| d == "P0106-64" && s & 1 == 1));
        // No change, no output.
        let n = events.len() + statuses.len();
        let mut quiet = 0;
        ev.report(
            1.1,
            &[Verdict::Failed, Verdict::Passed],
            &failed,
            &[],
            &mut |_| quiet += 1,
        );
        assert_eq!(quiet, 0, "{n} outputs before");
    }

    #[test]
    fn a_restored_memory_reports_only_changes_from_the_restored_statuses() {
        let failed = TestResult {
            value: 9.0,
            min: 0.0,
            max: 5.0,
            verdict: Verdict::Failed,
        };
        let mut ev = MonitorEvents::new(&specs()).expect("valid");
        for c in 0..2u64 {
            ev.start_operation_cycle(c * 10_000_000_000, &mut |_| {});
            let t = c as f64 * 10.0 + 1.0;
            ev.report(
                t,
                &[Verdict::Failed, Verdict::Passed],
                &failed,
                &[],
                &mut |_| {},
            );
            ev.end_operation_cycle(c * 10_000_000_000 + 5_000_000_000, &mut |_| {});
        }
        let image = ev.memory().image();
        let mut fresh = MonitorEvents::new(&specs()).expect("valid");
        assert!(fresh.restore(&image).nothing_dropped());
        assert!(fresh.memory().status(fresh.ids[0]).confirmed());
        // Same verdicts after the power-up: the bytes end where they were restored (0xAF,
        // 0x00), so nothing is reported (without the restored cache: 0x50 -> both).
        let mut statuses = Vec::new();
        fresh.start_operation_cycle(0, &mut |_| {});
        fresh.report(
            0.5,
            &[Verdict::Failed, Verdict::Passed],
            &failed,
            &[],
            &mut |o| {
                if let Output::DtcStatus { status, .. } = o {
                    statuses.push(status.byte());
                }
            },
        );
        assert!(statuses.is_empty(), "{statuses:x?}");
    }

    #[test]
    fn a_bad_dtc_is_an_error_naming_it() {
        let bad = [EventSpec {
            name: "a",
            dtc: "X9999",
            priority: 2,
        }];
        let e = MonitorEvents::new(&bad).expect_err("bad DTC").to_string();
        assert!(e.contains("X9999"), "{e}");
    }
}
