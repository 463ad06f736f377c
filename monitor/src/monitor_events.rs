//! The DTC side of a monitor: its own event memory, one event per DTC, the freeze frames its
//! DTCs store, and the status bytes forwarded as [`Output::DtcStatus`] when they change.
//!
//! - **Debounce**: subsystem monitors qualify their faults themselves (`MonitorInternal`: the
//!   monitor's persistence and decision logic is the debounce) and report one verdict per event
//!   every step; the "no signal" monitor may use a counter or time debounce instead.
//! - **Repeated verdicts**: with monitor-internal debounce, reporting the verdict an event
//!   already had changes nothing in the memory, so it is not passed on (a step in which no
//!   verdict changed costs a comparison per event). After an operation-cycle start, a clear or
//!   a restore every event is reported again.
//! - **Freeze frames**: each event stores, at its first qualified failure, the values of its
//!   configured freeze-frame items: runtime signals (their latest value) or estimates the
//!   monitor declares ([`FreezeSource`]). The runtime configures them after construction
//!   ([`MonitorEvents::configure_freeze_frames`]); until then events store none.
//!
//! Sized at construction; a step allocates nothing, status change or not.

use fdd_diagnostics::dtc::{
    DebounceConfig, DemError, Dtc, DtcGroup, EventConfig, EventId, EventMemory, EventMemoryConfig,
    MilConfig, ReportContext,
};
use fdd_diagnostics::{ConfigError, TestResult, Verdict};

use crate::monitor::{Output, OutputSink};
use crate::signal_table::{SignalId, SignalTable};

/// One event of a monitor: its name, its DTC (`P0106-64`), its memory priority (1 highest),
/// its debounce, and whether it requests the MIL (an information event, e.g. a road surface
/// class, is stored and reported but never lights the lamp).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EventSpec<'a> {
    pub name: &'a str,
    pub dtc: &'a str,
    pub priority: u8,
    pub debounce: DebounceConfig,
    pub mil: bool,
}

impl<'a> EventSpec<'a> {
    /// An event qualified by the monitor itself (the usual case).
    pub const fn internal(name: &'a str, dtc: &'a str, priority: u8) -> Self {
        EventSpec {
            name,
            dtc,
            priority,
            debounce: DebounceConfig::MonitorInternal,
            mil: true,
        }
    }

    /// An information event qualified by the monitor itself: stored with its status byte and
    /// freeze frame, never requesting the MIL.
    pub const fn information(name: &'a str, dtc: &'a str, priority: u8) -> Self {
        EventSpec {
            name,
            dtc,
            priority,
            debounce: DebounceConfig::MonitorInternal,
            mil: false,
        }
    }
}

/// Where a freeze-frame value comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FreezeSource {
    /// The latest value of a runtime signal (stale or not; NaN if it never arrived).
    Signal(SignalId),
    /// Estimate number `k` of the monitor's [`MonitorEvents::estimate_names`].
    Estimate(usize),
}

/// What fills a freeze frame at the moment of a failure: the signal table and the monitor's
/// current estimates (in the order of its estimate names).
#[derive(Clone, Copy)]
pub struct FreezeValues<'a> {
    pub signals: Option<&'a SignalTable>,
    pub estimates: &'a [f64],
}

impl FreezeValues<'_> {
    /// No values (every item NaN).
    pub const NONE: FreezeValues<'static> = FreezeValues {
        signals: None,
        estimates: &[],
    };

    fn value(&self, src: FreezeSource) -> f64 {
        match src {
            FreezeSource::Signal(id) => self
                .signals
                .and_then(|t| t.try_get(id))
                .map_or(f64::NAN, |s| s.value),
            FreezeSource::Estimate(k) => self.estimates.get(k).copied().unwrap_or(f64::NAN),
        }
    }
}

/// A monitor's event memory and the last status byte reported per event.
#[derive(Debug)]
pub struct MonitorEvents {
    memory: EventMemory,
    specs: Vec<OwnedSpec>,
    ids: Vec<EventId>,
    statuses: Vec<u8>,
    /// Last verdict passed to the memory per event; `None` = report the next one whatever it is.
    last: Vec<Option<Verdict>>,
    /// Freeze-frame sources per event.
    sources: Vec<Vec<FreezeSource>>,
    /// Scratch for the freeze-frame values of one report.
    ff_buf: Vec<f64>,
    estimate_names: Vec<&'static str>,
    /// Whether the running operation cycle counts as an aging cycle when it ends.
    aging_cycle: bool,
}

#[derive(Debug, Clone)]
struct OwnedSpec {
    name: String,
    dtc: String,
    priority: u8,
    debounce: DebounceConfig,
    mil: bool,
}

impl MonitorEvents {
    /// Memory entries (stored DTCs) a monitor keeps.
    pub const CAPACITY: usize = 8;

    /// Builds the memory: confirmation after 2 failed operation cycles, aging after 40, the
    /// default MIL policy, no freeze frame yet. Errors name the offending event key.
    pub fn new(specs: &[EventSpec<'_>]) -> Result<Self, ConfigError> {
        Self::with_capacity(specs, Self::CAPACITY)
    }

    /// [`MonitorEvents::new`] with `capacity` memory entries instead of [`Self::CAPACITY`].
    pub fn with_capacity(specs: &[EventSpec<'_>], capacity: usize) -> Result<Self, ConfigError> {
        let specs: Vec<OwnedSpec> = specs
            .iter()
            .map(|s| OwnedSpec {
                name: s.name.to_string(),
                dtc: s.dtc.to_string(),
                priority: s.priority,
                debounce: s.debounce,
                mil: s.mil,
            })
            .collect();
        let n = specs.len();
        let memory = Self::build_memory(&specs, &vec![Vec::new(); n], capacity)?;
        let ids = (0..n)
            .map(|i| {
                memory
                    .event_id_at(i)
                    .ok_or_else(|| ConfigError::new("events", i, "event missing from the memory"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            statuses: vec![0x50; n],
            last: vec![None; n],
            sources: vec![Vec::new(); n],
            ff_buf: Vec::new(),
            estimate_names: Vec::new(),
            aging_cycle: true,
            memory,
            specs,
            ids,
        })
    }

    fn build_memory(
        specs: &[OwnedSpec],
        freeze: &[Vec<String>],
        capacity: usize,
    ) -> Result<EventMemory, ConfigError> {
        let events = specs
            .iter()
            .zip(freeze)
            .map(|(s, ff)| EventConfig {
                name: s.name.clone(),
                dtc: s.dtc.clone(),
                priority: s.priority,
                debounce: s.debounce,
                confirmation_threshold: 2,
                aging_threshold: 40,
                mil: MilConfig {
                    enabled: s.mil,
                    ..MilConfig::default()
                },
                freeze_frame: ff.clone(),
                freeze_frame_update: Default::default(),
            })
            .collect();
        EventMemory::new(&EventMemoryConfig { capacity, events })
    }

    /// Declares the estimates the monitor can put in freeze frames (values passed in the same
    /// order with every report).
    pub fn with_estimates(mut self, names: &[&'static str]) -> Self {
        self.estimate_names = names.to_vec();
        self
    }

    /// The estimates the monitor offers to freeze frames.
    pub fn estimate_names(&self) -> &[&'static str] {
        &self.estimate_names
    }

    /// Sets each event's freeze frame: item names resolved to a signal of `table` or one of the
    /// monitor's estimates. Rebuilds the memory, so call it before the first operation cycle.
    /// `key(i)` names the configuration key of event `i`'s list in errors.
    pub fn configure_freeze_frames(
        &mut self,
        items: &[Vec<String>],
        table: &SignalTable,
        key: &dyn Fn(usize) -> String,
    ) -> Result<(), ConfigError> {
        if items.len() != self.specs.len() {
            return Err(ConfigError::new(
                "freeze_frames",
                items.len(),
                format!(
                    "{} events need {} lists",
                    self.specs.len(),
                    self.specs.len()
                ),
            ));
        }
        let mut sources = Vec::with_capacity(items.len());
        for (i, list) in items.iter().enumerate() {
            let mut src = Vec::with_capacity(list.len());
            for (j, name) in list.iter().enumerate() {
                let s = if let Some(id) = table.id(name) {
                    FreezeSource::Signal(id)
                } else if let Some(k) = self.estimate_names.iter().position(|e| e == name) {
                    FreezeSource::Estimate(k)
                } else {
                    return Err(ConfigError::new(
                        format!("{}[{j}]", key(i)),
                        format!("{name:?}"),
                        format!(
                            "is neither a runtime signal nor an estimate of this monitor ({})",
                            if self.estimate_names.is_empty() {
                                "it has none".to_string()
                            } else {
                                self.estimate_names.join(", ")
                            }
                        ),
                    ));
                };
                src.push(s);
            }
            sources.push(src);
        }
        self.memory = Self::build_memory(&self.specs, items, self.memory.capacity())?;
        self.ff_buf = vec![f64::NAN; sources.iter().map(Vec::len).max().unwrap_or(0)];
        self.sources = sources;
        self.statuses.fill(0x50);
        self.last.fill(None);
        Ok(())
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

    /// The name of event `i`.
    pub fn name(&self, i: usize) -> &str {
        &self.specs[i].name
    }

    /// The event memory (status bytes, entries, freeze frames, counters).
    pub fn memory(&self) -> &EventMemory {
        &self.memory
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
        values: FreezeValues<'_>,
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
            let cands = if verdict == Verdict::Failed {
                candidates
            } else {
                &[]
            };
            self.report_one(i, now_s, &result, cands, values, out);
        }
    }

    /// Reports event `i`'s result at `now_s` (see the module documentation for what is skipped).
    pub fn report_one(
        &mut self,
        i: usize,
        now_s: f64,
        result: &TestResult,
        candidates: &[(&str, f64)],
        values: FreezeValues<'_>,
        out: &mut OutputSink<'_>,
    ) {
        let Some(&id) = self.ids.get(i) else {
            return;
        };
        let verdict = result.verdict;
        if verdict == Verdict::NotTested {
            return;
        }
        let internal = self.specs[i].debounce == DebounceConfig::MonitorInternal;
        if internal && self.last[i] == Some(verdict) {
            return;
        }
        let n = self.sources[i].len();
        let ff: &[f64] = if verdict.leans_failed() && n > 0 {
            for (dst, &src) in self.ff_buf.iter_mut().zip(&self.sources[i]) {
                *dst = values.value(src);
            }
            &self.ff_buf[..n]
        } else {
            &[]
        };
        let ctx = ReportContext::at(now_s)
            .with_freeze_frame(ff)
            .with_candidates(candidates);
        let res = self
            .memory
            .report_view(id, result, &ctx, |e| out(Output::Event(e)));
        match res {
            Ok(status) => {
                self.last[i] = Some(verdict);
                if status.byte() != self.statuses[i] {
                    self.statuses[i] = status.byte();
                    out(Output::DtcStatus {
                        dtc: self.memory.dtc(id),
                        status,
                    });
                }
            }
            Err(e) => tracing::error!(
                event = %self.specs[i].name,
                "event memory refused a report: {e}"
            ),
        }
    }

    /// Forwards the status bytes that changed since the last forward.
    fn emit_status_changes(&mut self, out: &mut OutputSink<'_>) {
        for (i, &id) in self.ids.iter().enumerate() {
            let status = self.memory.status(id);
            if status.byte() != self.statuses[i] {
                self.statuses[i] = status.byte();
                out(Output::DtcStatus {
                    dtc: self.memory.dtc(id),
                    status,
                });
            }
        }
    }

    /// An operation cycle starts.
    pub fn start_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        self.last.fill(None);
        if let Err(e) = self
            .memory
            .start_operation_cycle_view(now_ns as f64 * 1e-9, |e| out(Output::Event(e)))
        {
            tracing::error!("cannot start the operation cycle: {e}");
        }
        self.emit_status_changes(out);
    }

    /// Whether the running operation cycle counts as an aging cycle when it ends (default
    /// true; a runtime that ages over warm-up cycles sets it from the host's warm-up report).
    pub fn set_aging_cycle(&mut self, aging_cycle: bool) {
        self.aging_cycle = aging_cycle;
    }

    /// The operation cycle ends.
    pub fn end_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        if let Err(e) =
            self.memory
                .end_operation_cycle_aging(now_ns as f64 * 1e-9, self.aging_cycle, |e| {
                    out(Output::Event(e))
                })
        {
            tracing::error!("cannot end the operation cycle: {e}");
        }
        self.emit_status_changes(out);
    }

    /// ClearDTC for `group` at `now_ns`: the events of this memory in the group go back to
    /// 0x50. Returns how many were cleared (0 when none is in the group: unlike the memory,
    /// a single DTC that is not here is not an error, since the runtime asks every monitor).
    pub fn clear(
        &mut self,
        group: DtcGroup,
        now_ns: u64,
        out: &mut OutputSink<'_>,
    ) -> Result<usize, DemError> {
        if let DtcGroup::Dtc(d) = group {
            if self.memory.event_id_by_dtc(d).is_none() {
                return Ok(0);
            }
        }
        let n = self
            .memory
            .clear_dtc_view(group, now_ns as f64 * 1e-9, |e| out(Output::Event(e)))?;
        self.last.fill(None);
        self.emit_status_changes(out);
        Ok(n)
    }

    /// Mutable access to the memory for restoring a persisted image; resets the report cache.
    pub fn memory_mut(&mut self) -> &mut EventMemory {
        self.last.fill(None);
        for (i, &id) in self.ids.iter().enumerate() {
            self.statuses[i] = self.memory.status(id).byte();
        }
        &mut self.memory
    }

    /// Restores a persisted image into the memory (see
    /// [`fdd_diagnostics::dtc::EventMemory::restore`]); call it before the first operation
    /// cycle. The restored status bytes become the last reported ones, so the next step reports
    /// only what changes from them.
    pub fn restore(
        &mut self,
        image: &fdd_diagnostics::dtc::MemoryImage,
    ) -> fdd_diagnostics::dtc::RestoreReport {
        let report = self.memory.restore(image);
        self.sync_statuses();
        report
    }

    /// Re-reads the status bytes after the memory was changed through [`Self::memory_mut`].
    pub fn sync_statuses(&mut self) {
        for (i, &id) in self.ids.iter().enumerate() {
            self.statuses[i] = self.memory.status(id).byte();
        }
        self.last.fill(None);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal_table::SignalSpec;
    use fdd_diagnostics::dtc::StatusBit;
    use fdd_diagnostics::event::DiagnosticEvent;

    fn specs() -> [EventSpec<'static>; 2] {
        [
            EventSpec::internal("a", "P0106-64", 2),
            EventSpec::internal("b", "P0401-00", 3),
        ]
    }

    fn failed() -> TestResult {
        TestResult {
            value: 9.0,
            min: 0.0,
            max: 5.0,
            verdict: Verdict::Failed,
        }
    }

    #[test]
    fn a_failed_verdict_raises_its_dtc_with_the_result_and_candidates() {
        let mut ev = MonitorEvents::new(&specs()).expect("valid");
        assert_eq!(ev.len(), 2);
        assert_eq!(ev.dtc(1).to_string(), "P0401-00");
        let mut events: Vec<DiagnosticEvent> = Vec::new();
        let mut statuses = Vec::new();
        let mut out = |o: Output<'_>| match o {
            Output::Event(e) => events.push(e.to_event()),
            Output::DtcStatus { dtc, status } => statuses.push((dtc.to_string(), status.byte())),
            _ => {}
        };
        ev.start_operation_cycle(0, &mut out);
        ev.report(
            1.0,
            &[Verdict::Failed, Verdict::Passed],
            &failed(),
            &[("map_sensor", 0.9), ("leak", 0.1)],
            FreezeValues::NONE,
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
            &failed(),
            &[],
            FreezeValues::NONE,
            &mut |_| quiet += 1,
        );
        assert_eq!(quiet, 0, "{n} outputs before");
    }

    #[test]
    fn freeze_frames_capture_signals_and_estimates_at_the_first_failure() {
        let mut table = SignalTable::new(vec![
            SignalSpec {
                name: "map".into(),
                max_age_ns: 10,
            },
            SignalSpec {
                name: "speed".into(),
                max_age_ns: 10,
            },
        ])
        .expect("table");
        let map = table.id("map").expect("map");
        table.set(map, 5, 101_000.0).expect("sample");
        let mut ev = MonitorEvents::new(&specs())
            .expect("valid")
            .with_estimates(&["manifold_pressure"]);
        let items = vec![
            vec![
                "map".to_string(),
                "speed".into(),
                "manifold_pressure".into(),
            ],
            vec![],
        ];
        ev.configure_freeze_frames(&items, &table, &|i| format!("events[{i}]"))
            .expect("resolves");
        let mut stored = Vec::new();
        let mut out = |o: Output<'_>| {
            if let Output::Event(e) = o {
                if e.raised() {
                    stored.push(e.to_event());
                }
            }
        };
        ev.start_operation_cycle(0, &mut out);
        let values = FreezeValues {
            signals: Some(&table),
            estimates: &[99_500.0],
        };
        ev.report(
            1.0,
            &[Verdict::Failed, Verdict::Passed],
            &failed(),
            &[],
            values,
            &mut out,
        );
        assert_eq!(stored.len(), 1);
        let ff: Vec<_> = stored[0]
            .freeze_frame
            .iter()
            .map(|f| (f.signal.as_str(), f.value))
            .collect();
        assert_eq!(
            ff,
            vec![
                ("map", Some(101_000.0)),
                ("speed", None),
                ("manifold_pressure", Some(99_500.0))
            ]
        );
        let entry = ev
            .memory()
            .entry(ev.memory().event_id_at(0).expect("id"))
            .expect("stored");
        assert_eq!(entry.freeze_frame().count(), 3);

        let bad = vec![vec!["nope".to_string()], vec![]];
        let e = ev
            .configure_freeze_frames(&bad, &table, &|i| format!("freeze_frames.events.e{i}"))
            .expect_err("unknown item")
            .to_string();
        assert!(
            e.contains("freeze_frames.events.e0[0]") && e.contains("nope"),
            "{e}"
        );
    }

    #[test]
    fn clear_resets_the_group_and_reports_again() {
        let mut ev = MonitorEvents::new(&specs()).expect("valid");
        let mut sink = |_: Output<'_>| {};
        ev.start_operation_cycle(0, &mut sink);
        ev.report(
            1.0,
            &[Verdict::Failed, Verdict::Passed],
            &failed(),
            &[],
            FreezeValues::NONE,
            &mut sink,
        );
        let id = ev.memory().event_id_at(0).expect("id");
        assert!(ev.memory().status(id).test_failed());
        let d = ev.dtc(0);
        assert_eq!(ev.clear(DtcGroup::Dtc(d), 2_000_000_000, &mut sink), Ok(1));
        assert_eq!(ev.memory().status(id).byte(), 0x50);
        // A DTC of another monitor is not an error here.
        let other: Dtc = "P0122-16".parse().expect("dtc");
        assert_eq!(
            ev.clear(DtcGroup::Dtc(other), 2_000_000_000, &mut sink),
            Ok(0)
        );
        // The same failed verdict is reported again after the clear.
        ev.report(
            3.0,
            &[Verdict::Failed, Verdict::Passed],
            &failed(),
            &[],
            FreezeValues::NONE,
            &mut sink,
        );
        assert!(ev.memory().status(id).test_failed());
    }

    #[test]
    fn a_bad_dtc_is_an_error_naming_it() {
        let bad = [EventSpec::internal("a", "X9999", 2)];
        let e = MonitorEvents::new(&bad).expect_err("bad DTC").to_string();
        assert!(e.contains("X9999"), "{e}");
    }
}
