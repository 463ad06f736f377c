//! The monitor plugin interface.
//!
//! A monitor is one physical subsystem's diagnosis: it declares the signals it reads and the
//! period it runs at, owns its estimators, detectors and DTC event memory, and reports what it
//! finds through [`Output`]s. The runtime ([`crate::scheduler::Scheduler`]) calls
//! [`Monitor::step`] at the monitor's rate with the current [`SignalTable`].

use fdd_diagnostics::dtc::{Dtc, DtcStatus};
use fdd_diagnostics::event::EventView;
use fdd_diagnostics::TestResult;

use crate::monitor_events::MonitorEvents;
use crate::signal_table::{SignalId, SignalTable};

/// Something a monitor reports during a step. Borrowed, so reporting allocates nothing; a sink
/// that keeps an output copies what it needs. Names of estimates, sources, filters and tests
/// are fixed by the monitor's code (`'static`), so a queued copy needs no allocation either.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Output<'a> {
    /// An estimate of a physical quantity with its 95 % interval, and where it comes from
    /// (e.g. the throttle angle in degrees, from `"tps"` or `"wattmeter_estimate"`).
    Estimate {
        name: &'static str,
        value: f64,
        lower: f64,
        upper: f64,
        source: &'static str,
    },
    /// One filter's innovation: residual per measurement component, its predicted variance,
    /// the NIS and its degrees of freedom.
    Innovation {
        filter: &'static str,
        residual: &'a [f64],
        variance: &'a [f64],
        nis: f64,
        dof: usize,
    },
    /// One test's result this step.
    Test {
        test: &'static str,
        result: TestResult,
    },
    /// A DTC's status byte after this step (reported when it changes).
    DtcStatus { dtc: Dtc, status: DtcStatus },
    /// A status change of the event memory (borrowed; [`EventView::to_event`] owns it).
    Event(&'a EventView<'a>),
    /// The monitor's diagnosis after this step, reported once per step: whether it considers
    /// its subsystem faulty now (`flagged`: a test is failing, a fault is being isolated or a
    /// decided fault is still present), and a score in `[0, 1]` per fault class of
    /// [`Monitor::fault_classes`] (how strongly it names each; all 0 when not flagged). This is
    /// the per-sample output that TDR, FAR and FIA are computed from (`fdd evaluate`).
    Diagnosis { flagged: bool, scores: &'a [f64] },
}

/// The sink a monitor reports into.
pub type OutputSink<'s> = dyn FnMut(Output<'_>) + 's;

/// A subsystem diagnosis run by the scheduler.
pub trait Monitor {
    /// Short name, used in logs and summaries (`throttle`).
    fn name(&self) -> &str;

    /// Period between steps (ns).
    fn period_ns(&self) -> u64;

    /// The signals the monitor reads (for staleness reporting and documentation).
    fn inputs(&self) -> &[SignalId];

    /// The fault classes its [`Output::Diagnosis`] scores, in the order of the scores (e.g.
    /// `tps_stuck`, `wattmeter`). Empty for a monitor that reports no diagnosis.
    fn fault_classes(&self) -> &'static [&'static str] {
        &[]
    }

    /// One step at time `now_ns`. Must not allocate in its steady state (no status change).
    fn step(&mut self, now_ns: u64, signals: &SignalTable, out: &mut OutputSink<'_>);

    /// An operation cycle starts (ignition on, or the start of a replayed log).
    fn start_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>);

    /// The operation cycle ends (ignition off, or the end of a replayed log).
    fn end_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>);

    /// The monitor's DTCs: its event memory, read by the runtime's DTC services and persisted.
    fn events(&self) -> &MonitorEvents;

    /// Mutable access to the DTCs (clear, restore, freeze-frame configuration).
    fn events_mut(&mut self) -> &mut MonitorEvents;

    /// The freeze frame its DTCs store unless the configuration says otherwise: names of
    /// runtime signals or of estimates the monitor declares in its [`MonitorEvents`].
    fn default_freeze_frame(&self) -> Vec<String> {
        Vec::new()
    }

    /// Some of its DTCs were cleared (UDS 0x14): restart the tests whose results were latched
    /// for the operation cycle, as AUTOSAR's `InitMonitorForEvent(DEM_INIT_MONITOR_CLEAR)`.
    fn restart_tests(&mut self, _now_ns: u64) {}

    /// Starts or stops watching another monitor's signal (its consumer was enabled or
    /// disabled). Only the "no signal" monitor watches signals it does not read itself.
    fn set_signal_watched(&mut self, _id: SignalId, _watched: bool) {}
}
