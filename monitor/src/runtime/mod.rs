//! The runtime a vehicle program embeds: the configured monitors, the signal table they read,
//! the "no signal" monitor, ring-buffer ingestion, operation cycles and the DTC services, in
//! the host's terms.
//!
//! - **Samples**: resolve each signal's name once ([`Runtime::signal`]), then
//!   [`Runtime::push`] costs a bounds check and a store. Tasks on other threads push into
//!   single-producer queues instead ([`RuntimeBuilder::queue`], [`SampleProducer`]).
//! - **Time** is the host's clock in ns, never the wall clock: [`Runtime::advance_to`]`(t)`
//!   drains the queues in time order and runs every monitor step due at or before `t`, in time
//!   order across monitors. A step at time `T` sees the latest sample of each signal pushed
//!   before the call (queued samples: exactly those stamped `<= T`).
//! - **Operation cycles** are the host's (ignition on/off, as AUTOSAR Dem's
//!   `Dem_RestartOperationCycle`): [`Runtime::start_operation_cycle`],
//!   [`Runtime::end_operation_cycle`]. Monitors run only inside one.
//! - **Outputs** go to a [`Sink`] the host supplies: a closure, or an [`EventQueue`] drained
//!   later. Nothing on the push / advance / drain path allocates.
//! - **DTC services** with UDS semantics: DTCs by status mask (0x19 0x02), the status
//!   availability mask, freeze frames (snapshot, 0x19 0x04), extended data (occurrence
//!   counter, aging counter, max FDC; 0x19 0x06), ClearDiagnosticInformation (0x14) for one DTC,
//!   a system (P/C/B/U) or all; and monitors enabled or disabled at run time.
//!
//! ```
//! use fdd_monitor::runtime::{Runtime, Stamped};
//! use fdd_monitor::monitor::Output;
//!
//! let mut rt = Runtime::with_defaults().expect("embedded configuration");
//! let (u, tps, watt) = (
//!     rt.signal("motor_voltage").unwrap(),
//!     rt.signal("tps").unwrap(),
//!     rt.signal("wattmeter").unwrap(),
//! );
//! let mut raised = Vec::new();
//! let mut sink = |o: Stamped<'_>| {
//!     if let Output::Event(e) = o.output {
//!         if e.raised() {
//!             raised.push(e.dtc);
//!         }
//!     }
//! };
//! rt.start_operation_cycle(0, &mut sink).unwrap();
//! for k in 0..300u64 {
//!     let t = k * 1_000_000; // 1 kHz
//!     rt.push(u, t, 0.0).unwrap();
//!     rt.push(tps, t, 0.0).unwrap(); // closed plate: 0 V
//!     rt.push(watt, t, 0.0).unwrap();
//!     rt.advance_to(t, &mut sink).unwrap();
//! }
//! // DTCs with pendingDTC set (UDS 0x19 0x02, mask 0x04).
//! let pending: Vec<_> = rt.dtcs_by_status_mask(0x04).collect();
//! assert!(!pending.is_empty());
//! rt.end_operation_cycle(300_000_000, &mut sink).unwrap();
//! // The intake signals never arrived: their "no signal" DTCs (failure type 0x31).
//! assert!(raised.iter().any(|d| d.to_string() == "P0105-31"));
//! ```

pub mod config;
mod ingest;
mod sink;
pub mod uds;

use std::path::Path;

use fdd_diagnostics::dtc::{DemError, Dtc, DtcGroup, DtcStatus, MemoryEntry};

use crate::config::ConfigError;
use crate::monitor::Monitor;
use crate::monitor_events::MonitorEvents;
use crate::scheduler::Scheduler;
use crate::signal_table::{SampleError, SignalId, SignalTable};
use crate::staleness::StalenessMonitor;

pub use config::{ReadLimits, RuntimeConfig};
pub use ingest::{QueueStats, QueuedSample, SampleProducer};
pub use sink::{EstimateRecord, EventQueue, EventRecord, NullSink, Sink, Stamped};
pub use uds::UdsServer;

use ingest::{IngestionMonitor, Queue};

/// Why the runtime could not be built or refused a call. A refused call changes nothing.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// A monitor could not be built from its configuration.
    #[error("{origin}: monitor `{monitor}`: {message}")]
    Monitor {
        origin: String,
        monitor: String,
        message: String,
    },
    /// Two events of the runtime share a DTC (the DTC services could not tell them apart);
    /// the message names the configuration, the DTC and both events with their monitors.
    #[error("{0}")]
    DuplicateDtc(String),
    /// `push` with an id that is not one of this runtime's signals.
    #[error("signal id {0} is not a signal of this runtime")]
    UnknownSignal(usize),
    /// The signal table refused a sample.
    #[error("{signal} at {t_ns} ns: sample refused: {source}")]
    Sample {
        /// The signal (its name: [`Runtime::signals`]`.spec(id)`); an id, so that refusing a
        /// sample on the host path allocates nothing.
        signal: SignalId,
        t_ns: u64,
        #[source]
        source: SampleError,
    },
    /// The host's time went backwards.
    #[error("time {t_ns} ns is before the runtime's time {now_ns} ns")]
    TimeWentBackwards { t_ns: u64, now_ns: u64 },
    /// `advance_to` or `end_operation_cycle` without a running operation cycle.
    #[error("no operation cycle is running (call start_operation_cycle first)")]
    NoOperationCycle,
    /// A monitor name that is not in this runtime.
    #[error("no monitor `{0}` in this runtime (it has: {1})")]
    UnknownMonitor(String, String),
    /// ClearDTC of a single DTC that no event has.
    #[error("DTC {0} is not configured in this runtime")]
    UnknownDtc(Dtc),
    /// The event memory refused a call.
    #[error("event memory: {0}")]
    Memory(#[from] DemError),
    /// The persisted event memory could not be opened or written.
    #[error("event memory persistence: {0}")]
    Persist(#[from] crate::persist::PersistError),
}

/// Extended data of one DTC (UDS 0x19 0x06 records).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExtendedData {
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

/// Where an event lives: (monitor index, event index in its memory).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct EventRef {
    dtc: Dtc,
    monitor: usize,
    event: usize,
}

/// A queue to create at construction.
#[derive(Debug, Clone)]
struct QueueSpec {
    name: String,
    capacity: usize,
    dtc: String,
}

/// Builds a [`Runtime`]: the configuration plus what a host decides at construction (which
/// monitors run, the ingestion queues).
#[derive(Debug, Clone)]
pub struct RuntimeBuilder {
    cfg: RuntimeConfig,
    only: Option<Vec<String>>,
    queues: Vec<QueueSpec>,
    ingestion_period_ns: u64,
    persistence: Option<std::path::PathBuf>,
    detail: bool,
}

impl RuntimeBuilder {
    /// Keeps the event memory across power cycles in two slot files `<base>.a` / `<base>.b`
    /// ([`crate::persist::SlotStore`]): restored at construction (what still matches the DTC
    /// configuration; [`Runtime::restore_notes`] says what was dropped), written at every
    /// operation-cycle end, when a DTC becomes confirmed and after a ClearDTC.
    pub fn persistence(mut self, base: impl Into<std::path::PathBuf>) -> Self {
        self.persistence = Some(base.into());
        self
    }

    /// Only these of the enabled subsystem monitors are built (the "no signal" monitor always
    /// is, watching the signals of the monitors built).
    pub fn only_monitors(mut self, names: &[&str]) -> Self {
        self.only = Some(names.iter().map(|s| s.to_string()).collect());
        self
    }

    /// Adds an ingestion queue of `capacity` samples for one producing task. Its "samples
    /// lost" event gets `dtc` (e.g. `P1680-00`, a manufacturer code).
    pub fn queue(mut self, name: &str, capacity: usize, dtc: &str) -> Self {
        self.queues.push(QueueSpec {
            name: name.to_string(),
            capacity,
            dtc: dtc.to_string(),
        });
        self
    }

    /// Whether the sink receives every step's innovations, test statistics and diagnoses
    /// ([`crate::monitor::Output::Diagnosis`]; default true);
    /// without them it still gets events, status bytes and estimates, for less work per step.
    pub fn detail_outputs(mut self, on: bool) -> Self {
        self.detail = on;
        self
    }

    /// Period of the check of the queues' loss counters (default 10 ms).
    pub fn ingestion_check_period_ns(mut self, period_ns: u64) -> Self {
        self.ingestion_period_ns = period_ns.max(1);
        self
    }

    /// Builds the runtime and the producers of its queues (in the order they were added).
    pub fn build(self) -> Result<(Runtime, Vec<SampleProducer>), RuntimeError> {
        Runtime::build(self)
    }
}

/// One runtime: see the [module documentation](self).
pub struct Runtime {
    origin: String,
    table: SignalTable,
    sched: Scheduler,
    names: Vec<String>,
    /// Index of the "no signal" monitor in the scheduler.
    staleness: usize,
    dtcs: Vec<EventRef>,
    queues: Vec<Queue>,
    /// Time up to which steps have run (the latest `advance_to`), ns.
    now_ns: Option<u64>,
    cycle_active: bool,
    cycles: u32,
    store: Option<Persistence>,
    aging: config::AgingCycle,
    warmed_up: bool,
}

/// The persisted event memory: the slot store and a reusable buffer.
struct Persistence {
    store: crate::persist::SlotStore,
    buf: Vec<u8>,
    /// Sections of monitors that are not in this runtime (disabled, or not run on this log),
    /// written back unchanged so that their DTCs are not lost.
    carried: Vec<(String, Vec<u8>)>,
    notes: Vec<String>,
    writes: u64,
    failures: u64,
}

impl std::fmt::Debug for Runtime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Runtime")
            .field("origin", &self.origin)
            .field("monitors", &self.names)
            .field("now_ns", &self.now_ns)
            .field("cycle_active", &self.cycle_active)
            .finish()
    }
}

impl Runtime {
    /// A builder over `cfg`.
    pub fn builder(cfg: RuntimeConfig) -> RuntimeBuilder {
        RuntimeBuilder {
            cfg,
            only: None,
            queues: Vec::new(),
            ingestion_period_ns: 10_000_000,
            persistence: None,
            detail: true,
        }
    }

    /// The runtime of `cfg`, every enabled monitor, no queue.
    pub fn new(cfg: &RuntimeConfig) -> Result<Self, RuntimeError> {
        Ok(Self::builder(cfg.clone()).build()?.0)
    }

    /// The runtime of the embedded default configuration (`config/fdd.toml`).
    pub fn with_defaults() -> Result<Self, RuntimeError> {
        Self::new(&RuntimeConfig::embedded()?)
    }

    /// The runtime of a configuration text; `origin` names it in errors.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self, RuntimeError> {
        Self::new(&RuntimeConfig::parse(text, origin)?)
    }

    /// The runtime of a configuration file.
    pub fn from_file(path: &Path) -> Result<Self, RuntimeError> {
        Self::new(&RuntimeConfig::load(Some(path))?)
    }

    fn build(b: RuntimeBuilder) -> Result<(Runtime, Vec<SampleProducer>), RuntimeError> {
        let cfg = &b.cfg;
        let origin = cfg.origin.clone();
        let table = cfg.signal_table()?;
        let wanted = |name: &str| b.only.as_ref().is_none_or(|o| o.iter().any(|n| n == name));
        let mut subsystems: Vec<Box<dyn Monitor>> = Vec::new();
        if cfg.monitors.throttle && wanted("throttle") {
            subsystems.push(Box::new(throttle_monitor(cfg, &table)?));
        }
        if cfg.monitors.intake && wanted("intake") {
            subsystems.push(Box::new(intake_monitor(cfg, &table)?));
        }
        if cfg.monitors.turbo && wanted("turbo") {
            subsystems.push(Box::new(turbo_monitor(cfg, &table)?));
        }
        if cfg.monitors.wheel && wanted("wheel") {
            subsystems.push(Box::new(wheel_monitor(cfg, &table)?));
        }
        let mut watch: Vec<SignalId> = Vec::new();
        for m in &subsystems {
            for &id in m.inputs() {
                if !watch.contains(&id) {
                    watch.push(id);
                }
            }
        }
        let monitor_err = |monitor: &str, message: String| RuntimeError::Monitor {
            origin: origin.clone(),
            monitor: monitor.to_string(),
            message,
        };
        let staleness = StalenessMonitor::from_config(cfg, &table, &watch)
            .map_err(|e| monitor_err(StalenessMonitor::NAME, e.to_string()))?;
        let mut monitors: Vec<Box<dyn Monitor>> = vec![Box::new(staleness)];
        monitors.extend(subsystems);

        let mut queues = Vec::with_capacity(b.queues.len());
        let mut producers = Vec::with_capacity(b.queues.len());
        for q in &b.queues {
            let (queue, producer) = Queue::new(&q.name, q.capacity, table.len());
            queues.push(queue);
            producers.push(producer);
        }
        if !queues.is_empty() {
            let pairs: Vec<(&Queue, &str)> = queues
                .iter()
                .zip(&b.queues)
                .map(|(q, s)| (q, s.dtc.as_str()))
                .collect();
            let ing = IngestionMonitor::new(&pairs, b.ingestion_period_ns)
                .map_err(|e| monitor_err(IngestionMonitor::NAME, e.to_string()))?;
            monitors.push(Box::new(ing));
        }

        configure_freeze_frames(cfg, &table, &mut monitors)?;

        let mut sched = Scheduler::new(0);
        sched.set_detail(b.detail);
        let mut names = Vec::new();
        for m in monitors {
            names.push(m.name().to_string());
            sched
                .add(m)
                .map_err(|e| monitor_err(&names[names.len() - 1], e.to_string()))?;
        }
        let mut dtcs: Vec<EventRef> = Vec::new();
        for mi in 0..sched.len() {
            let ev = sched.monitor(mi).events();
            for ei in 0..ev.len() {
                let dtc = ev.dtc(ei);
                if let Some(first) = dtcs.iter().find(|r| r.dtc == dtc) {
                    return Err(RuntimeError::DuplicateDtc(format!(
                        "{origin}: DTC {dtc} is used by event `{}` ({}) and by `{}` ({})",
                        sched.monitor(first.monitor).events().name(first.event),
                        names[first.monitor],
                        ev.name(ei),
                        names[mi]
                    )));
                }
                dtcs.push(EventRef {
                    dtc,
                    monitor: mi,
                    event: ei,
                });
            }
        }
        for (name, m) in names.iter().zip(sched.monitors()) {
            tracing::info!(
                monitor = %name,
                "monitor `{name}` started: period {} ms, {} inputs, {} DTCs",
                m.period_ns() as f64 * 1e-6,
                m.inputs().len(),
                m.events().len()
            );
        }
        let store = match &b.persistence {
            None => None,
            Some(base) => Some(restore(base, &mut sched, &names)?),
        };
        Ok((
            Runtime {
                origin,
                table,
                sched,
                names,
                staleness: 0,
                dtcs,
                queues,
                now_ns: None,
                cycle_active: false,
                cycles: 0,
                store,
                aging: cfg.operation_cycles.aging,
                warmed_up: false,
            },
            producers,
        ))
    }

    // ------------------------------------------------------------------ signals and time

    /// The id of a signal by its configured name (resolve once, push many times).
    pub fn signal(&self, name: &str) -> Option<SignalId> {
        self.table.id(name)
    }

    /// The signal table (latest value and time of every signal).
    pub fn signals(&self) -> &SignalTable {
        &self.table
    }

    /// Stores a sample: a bounds check and a store. Refused (and counted by the caller) when
    /// the id is not this runtime's, the value is not finite, or its time does not increase.
    pub fn push(&mut self, signal: SignalId, t_ns: u64, value: f64) -> Result<(), RuntimeError> {
        if signal.index() >= self.table.len() {
            return Err(RuntimeError::UnknownSignal(signal.index()));
        }
        self.table
            .set(signal, t_ns, value)
            .map_err(|source| RuntimeError::Sample {
                signal,
                t_ns,
                source,
            })
    }

    /// Drains the queues in time order and runs every step due at or before `t_ns`. Returns
    /// the number of steps run. Outside an operation cycle, or with `t_ns` before the previous
    /// call's time, nothing happens and the call is refused.
    pub fn advance_to(&mut self, t_ns: u64, sink: &mut dyn Sink) -> Result<u64, RuntimeError> {
        if !self.cycle_active {
            return Err(RuntimeError::NoOperationCycle);
        }
        if let Some(now) = self.now_ns {
            if t_ns < now {
                return Err(RuntimeError::TimeWentBackwards { t_ns, now_ns: now });
            }
        }
        let Runtime {
            table,
            sched,
            names,
            queues,
            now_ns,
            ..
        } = self;
        let mut confirmed = false;
        let mut out = |i: usize, t: u64, o: crate::monitor::Output<'_>| {
            if let crate::monitor::Output::Event(e) = o {
                confirmed |= !e.status_before.confirmed() && e.status_after.confirmed();
            }
            sink.output(Stamped {
                t_ns: t,
                monitor: &names[i],
                output: o,
            })
        };
        let mut ran = 0;
        let now = now_ns.unwrap_or(0);
        // Queued samples, oldest first across queues (ties: queue order).
        loop {
            let mut best: Option<(usize, u64)> = None;
            for (k, q) in queues.iter_mut().enumerate() {
                if let Some(s) = q.peek() {
                    if s.t_ns <= t_ns && best.is_none_or(|(_, bt)| s.t_ns < bt) {
                        best = Some((k, s.t_ns));
                    }
                }
            }
            let Some((k, ts)) = best else { break };
            ran += sched.run_until(ts, table, &mut out);
            let q = &mut queues[k];
            if let Some(s) = q.head.take() {
                if s.t_ns < now {
                    q.late += 1;
                }
                match table.set(s.signal, s.t_ns, s.value) {
                    Ok(()) => q.applied += 1,
                    Err(_) => q.rejected += 1,
                }
            }
        }
        ran += sched.run_until(t_ns.saturating_add(1), table, &mut out);
        *now_ns = Some(t_ns);
        if confirmed {
            self.persist();
        }
        Ok(ran)
    }

    /// The time of the latest [`Runtime::advance_to`], ns.
    pub fn now_ns(&self) -> Option<u64> {
        self.now_ns
    }

    // ------------------------------------------------------------------ operation cycles

    /// Starts an operation cycle at `t_ns` (ending the running one first, as
    /// `Dem_RestartOperationCycle`): every monitor restarts its tests and its first step falls
    /// at `t_ns`.
    pub fn start_operation_cycle(
        &mut self,
        t_ns: u64,
        sink: &mut dyn Sink,
    ) -> Result<(), RuntimeError> {
        self.check_time(t_ns)?;
        if self.cycle_active {
            self.end_operation_cycle(t_ns, sink)?;
        }
        self.sched.restart(t_ns);
        self.warmed_up = false;
        self.for_each_monitor(t_ns, sink, |m, t, out| m.start_operation_cycle(t, out));
        self.cycle_active = true;
        self.cycles += 1;
        self.now_ns = Some(self.now_ns.map_or(t_ns, |n| n.max(t_ns)));
        tracing::info!(
            "operation cycle {} starts at {:.6} s",
            self.cycles,
            t_ns as f64 * 1e-9
        );
        Ok(())
    }

    /// Ends the running operation cycle at `t_ns` (pending DTCs of tests that passed are
    /// cleared, healing and aging counted). Steps due before `t_ns` that were not advanced to
    /// do not run.
    pub fn end_operation_cycle(
        &mut self,
        t_ns: u64,
        sink: &mut dyn Sink,
    ) -> Result<(), RuntimeError> {
        if !self.cycle_active {
            return Err(RuntimeError::NoOperationCycle);
        }
        self.check_time(t_ns)?;
        let aging = self.aging == config::AgingCycle::OperationCycle || self.warmed_up;
        for i in 0..self.sched.len() {
            self.sched
                .monitor_mut(i)
                .events_mut()
                .set_aging_cycle(aging);
        }
        self.for_each_monitor(t_ns, sink, |m, t, out| m.end_operation_cycle(t, out));
        self.cycle_active = false;
        self.now_ns = Some(t_ns);
        self.persist();
        tracing::info!(
            "operation cycle {} ends at {:.6} s",
            self.cycles,
            t_ns as f64 * 1e-9
        );
        Ok(())
    }

    /// The host reports that the running operation cycle is a warm-up cycle (OBD: coolant up
    /// by 22 degC to at least 70 degC). With `[operation_cycles] aging = "warm_up_cycle"` only
    /// such cycles age DTCs; otherwise this changes nothing.
    pub fn warm_up_completed(&mut self) {
        self.warmed_up = true;
    }

    /// Whether an operation cycle is running.
    pub fn operation_cycle_active(&self) -> bool {
        self.cycle_active
    }

    /// Operation cycles started so far.
    pub fn operation_cycles(&self) -> u32 {
        self.cycles
    }

    fn check_time(&self, t_ns: u64) -> Result<(), RuntimeError> {
        match self.now_ns {
            Some(now) if t_ns < now => Err(RuntimeError::TimeWentBackwards { t_ns, now_ns: now }),
            _ => Ok(()),
        }
    }

    fn for_each_monitor(
        &mut self,
        t_ns: u64,
        sink: &mut dyn Sink,
        mut f: impl FnMut(&mut dyn Monitor, u64, &mut crate::monitor::OutputSink<'_>),
    ) {
        for i in 0..self.sched.len() {
            let name = &self.names[i];
            let m = self.sched.monitor_mut(i);
            f(m, t_ns, &mut |o| {
                sink.output(Stamped {
                    t_ns,
                    monitor: name,
                    output: o,
                })
            });
        }
    }

    // ------------------------------------------------------------------ monitors

    /// The monitors' names, in step order (the "no signal" monitor first).
    pub fn monitor_names(&self) -> impl Iterator<Item = &str> {
        self.names.iter().map(String::as_str)
    }

    /// The fault classes the monitor `name` scores in its [`crate::monitor::Output::Diagnosis`]
    /// (empty for one that reports no diagnosis), or `None` for a name not in the runtime.
    pub fn fault_classes(&self, name: &str) -> Option<&'static [&'static str]> {
        let i = self.names.iter().position(|n| n == name)?;
        Some(self.sched.monitor(i).fault_classes())
    }

    /// The estimates the monitor `name` outputs and offers to freeze frames (e.g.
    /// `throttle_angle`), or `None` for a name not in the runtime.
    pub fn estimate_names(&self, name: &str) -> Option<&[&'static str]> {
        let i = self.names.iter().position(|n| n == name)?;
        Some(self.sched.monitor(i).events().estimate_names())
    }

    /// Steps run per monitor: `(name, steps)`.
    pub fn step_counts(&self) -> impl Iterator<Item = (&str, u64)> {
        self.sched.step_counts()
    }

    /// The signals the "no signal" monitor watches (the inputs of the enabled monitors).
    pub fn watched_signals(&self) -> &[SignalId] {
        self.sched.monitor(self.staleness).inputs()
    }

    /// Enables or disables a subsystem monitor at run time. A disabled monitor is not stepped
    /// and its DTCs keep their status; its signals are no longer watched for staleness unless
    /// another enabled monitor reads them.
    pub fn set_monitor_enabled(&mut self, name: &str, on: bool) -> Result<(), RuntimeError> {
        let Some(i) = self.names.iter().position(|n| n == name) else {
            return Err(RuntimeError::UnknownMonitor(
                name.to_string(),
                self.names.join(", "),
            ));
        };
        if i == self.staleness {
            return Err(RuntimeError::UnknownMonitor(
                format!("{name} (the \"no signal\" monitor always runs)"),
                self.names.join(", "),
            ));
        }
        let now = self.now_ns.unwrap_or(0);
        self.sched.set_enabled(i, on, now);
        let inputs: Vec<SignalId> = self.sched.monitor(i).inputs().to_vec();
        for id in inputs {
            let used_elsewhere = (0..self.sched.len()).any(|j| {
                j != i
                    && j != self.staleness
                    && self.sched.enabled(j)
                    && self.sched.monitor(j).inputs().contains(&id)
            });
            if !used_elsewhere {
                self.sched
                    .monitor_mut(self.staleness)
                    .set_signal_watched(id, on);
            }
        }
        tracing::info!(
            "monitor `{name}` {}",
            if on { "enabled" } else { "disabled" }
        );
        Ok(())
    }

    /// Whether a monitor is enabled (`None`: no such monitor).
    pub fn monitor_enabled(&self, name: &str) -> Option<bool> {
        let i = self.names.iter().position(|n| n == name)?;
        Some(self.sched.enabled(i))
    }

    // ------------------------------------------------------------------ DTC services

    /// ISO 14229-1 DTCStatusAvailabilityMask: fdd supports all eight status bits.
    pub fn status_availability_mask(&self) -> u8 {
        0xFF
    }

    /// Every DTC of the runtime with its status byte, in monitor order then configuration
    /// order.
    pub fn dtcs(&self) -> impl Iterator<Item = (Dtc, DtcStatus)> + '_ {
        self.dtcs.iter().map(|r| {
            let ev = self.sched.monitor(r.monitor).events();
            (r.dtc, ev.memory().status(event_id(ev, r.event)))
        })
    }

    /// UDS ReadDTCInformation 0x19 0x02: the DTCs whose status byte has any bit of `mask`
    /// (masked with the availability mask) set.
    pub fn dtcs_by_status_mask(&self, mask: u8) -> impl Iterator<Item = (Dtc, DtcStatus)> + '_ {
        let mask = mask & self.status_availability_mask();
        self.dtcs().filter(move |(_, s)| s.matches(mask))
    }

    fn find(&self, dtc: Dtc) -> Option<(&MonitorEvents, usize)> {
        let r = self.dtcs.iter().find(|r| r.dtc == dtc)?;
        Some((self.sched.monitor(r.monitor).events(), r.event))
    }

    /// The configured name of the event with `dtc`, and its monitor.
    pub fn event_name(&self, dtc: Dtc) -> Option<(&str, &str)> {
        let r = self.dtcs.iter().find(|r| r.dtc == dtc)?;
        Some((
            self.sched.monitor(r.monitor).events().name(r.event),
            &self.names[r.monitor],
        ))
    }

    /// The status byte of `dtc`.
    pub fn status(&self, dtc: Dtc) -> Option<DtcStatus> {
        let (ev, i) = self.find(dtc)?;
        Some(ev.memory().status(event_id(ev, i)))
    }

    /// The memory entry of `dtc` (freeze frame, counters), if it has one (UDS 0x19 0x04).
    pub fn freeze_frame(&self, dtc: Dtc) -> Option<MemoryEntry<'_>> {
        let (ev, i) = self.find(dtc)?;
        ev.memory().entry(event_id(ev, i))
    }

    /// Extended data of `dtc` (UDS 0x19 0x06).
    pub fn extended_data(&self, dtc: Dtc) -> Option<ExtendedData> {
        let (ev, i) = self.find(dtc)?;
        let info = ev.memory().event_info(event_id(ev, i));
        Some(ExtendedData {
            occurrence_counter: info.occurrence_counter,
            aging_counter: info.aging_counter,
            max_fdc: info.max_fdc,
            fdc: info.fdc,
            stored: info.stored,
        })
    }

    /// Every monitor's event memory: `(monitor name, events)`.
    pub fn event_memories(&self) -> impl Iterator<Item = (&str, &MonitorEvents)> {
        self.names
            .iter()
            .map(String::as_str)
            .zip(self.sched.monitors().map(|m| m.events()))
    }

    /// UDS ClearDiagnosticInformation (0x14) at `t_ns`: the DTCs of `group` go back to 0x50,
    /// their entries and counters erased; the monitors that owned them restart their latched
    /// tests. Returns the number of DTCs cleared.
    pub fn clear_dtc(
        &mut self,
        group: DtcGroup,
        t_ns: u64,
        sink: &mut dyn Sink,
    ) -> Result<usize, RuntimeError> {
        if let DtcGroup::Dtc(d) = group {
            if !self.dtcs.iter().any(|r| r.dtc == d) {
                return Err(RuntimeError::UnknownDtc(d));
            }
        }
        self.check_time(t_ns)?;
        let mut total = 0;
        for i in 0..self.sched.len() {
            let name = &self.names[i];
            let m = self.sched.monitor_mut(i);
            let n = m.events_mut().clear(group, t_ns, &mut |o| {
                sink.output(Stamped {
                    t_ns,
                    monitor: name,
                    output: o,
                })
            })?;
            if n > 0 {
                m.restart_tests(t_ns);
            }
            total += n;
        }
        tracing::info!(
            "ClearDTC ({group:?}) at {:.6} s: {total} DTCs",
            t_ns as f64 * 1e-9
        );
        self.persist();
        Ok(total)
    }

    // ------------------------------------------------------------------ persistence

    /// Writes the event memory to the older slot now (the runtime also does at cycle end, at
    /// a confirmation and after a clear). A failure leaves the other slot current; `Ok(false)`
    /// without persistence.
    pub fn persist_now(&mut self) -> Result<bool, RuntimeError> {
        let Some(p) = self.store.as_mut() else {
            return Ok(false);
        };
        p.buf.clear();
        let mut w = crate::persist::SectionWriter::new(&mut p.buf);
        for (name, m) in self.names.iter().zip(self.sched.monitors()) {
            let mem = m.events().memory();
            if let Err(e) = w.section(name, |b| mem.encode_image(b)) {
                p.failures += 1;
                return Err(RuntimeError::Monitor {
                    origin: self.origin.clone(),
                    monitor: name.clone(),
                    message: format!("cannot persist its event memory: {e}"),
                });
            }
        }
        for (name, bytes) in &p.carried {
            if let Err(e) = w.section(name, |b| b.extend_from_slice(bytes)) {
                p.failures += 1;
                return Err(RuntimeError::Monitor {
                    origin: self.origin.clone(),
                    monitor: name.clone(),
                    message: format!("cannot persist its event memory: {e}"),
                });
            }
        }
        w.finish();
        match p.store.write(&p.buf) {
            Ok(_) => {
                p.writes += 1;
                Ok(true)
            }
            Err(e) => {
                p.failures += 1;
                Err(e.into())
            }
        }
    }

    fn persist(&mut self) {
        if let Err(e) = self.persist_now() {
            tracing::error!("{e}");
        }
    }

    /// What the restore at construction found and did (slot problems, events dropped because
    /// the DTC configuration changed); empty without persistence or after a clean restore.
    pub fn restore_notes(&self) -> &[String] {
        self.store.as_ref().map_or(&[], |p| p.notes.as_slice())
    }

    /// Successful and failed writes of the persisted memory so far.
    pub fn persist_counts(&self) -> (u64, u64) {
        self.store
            .as_ref()
            .map_or((0, 0), |p| (p.writes, p.failures))
    }

    // ------------------------------------------------------------------ queues

    /// What happened to each queue's samples.
    pub fn queue_stats(&self) -> Vec<QueueStats> {
        self.queues.iter().map(Queue::stats).collect()
    }

    /// Where the configuration came from.
    pub fn origin(&self) -> &str {
        &self.origin
    }
}

/// Opens the slot store for the runtime's DTC configuration and restores each monitor's
/// memory from the current slot.
fn restore(
    base: &Path,
    sched: &mut Scheduler,
    names: &[String],
) -> Result<Persistence, RuntimeError> {
    let mut hasher = crate::persist::ConfigHasher::new();
    for (i, name) in names.iter().enumerate() {
        let ev = sched.monitor(i).events();
        for k in 0..ev.len() {
            hasher.event(name, ev.name(k), ev.dtc(k));
        }
    }
    let (store, recovered) = crate::persist::SlotStore::open(base, hasher.finish())?;
    let mut notes: Vec<String> = recovered.notes.iter().map(|n| n.to_string()).collect();
    let mut carried: Vec<(String, Vec<u8>)> = Vec::new();
    if let Some(cur) = &recovered.current {
        if !cur.config_matches {
            notes.push(format!(
                "{}: written for another DTC configuration: restoring the events that still match",
                cur.path.display()
            ));
        }
        match crate::persist::unpack_sections(&cur.payload) {
            Err(e) => notes.push(format!("{}: {e}", cur.path.display())),
            Ok(sections) => {
                for (section, bytes) in sections {
                    let Some(i) = names.iter().position(|n| n == section) else {
                        notes.push(format!(
                            "{}: monitor `{section}` is not in this runtime: its DTCs are kept as they are",
                            cur.path.display()
                        ));
                        carried.push((section.to_string(), bytes.to_vec()));
                        continue;
                    };
                    match fdd_diagnostics::dtc::MemoryImage::decode(bytes) {
                        Err(e) => {
                            notes.push(format!("{}: monitor `{section}`: {e}", cur.path.display()))
                        }
                        Ok(image) => {
                            let report = sched.monitor_mut(i).events_mut().restore(&image);
                            notes.extend(
                                report
                                    .dropped
                                    .iter()
                                    .map(|d| format!("monitor `{section}`: dropped {d}")),
                            );
                        }
                    }
                }
            }
        }
        tracing::info!(
            "event memory restored from {} (seq {})",
            cur.path.display(),
            cur.seq
        );
    }
    for n in &notes {
        tracing::warn!("{n}");
    }
    Ok(Persistence {
        store,
        buf: Vec::with_capacity(64 * 1024),
        carried,
        notes,
        writes: 0,
        failures: 0,
    })
}

fn event_id(ev: &MonitorEvents, i: usize) -> fdd_diagnostics::dtc::EventId {
    ev.memory()
        .event_id_at(i)
        .unwrap_or_else(|| unreachable!("event {i} was counted from this memory"))
}

/// Resolves `[freeze_frames]` for every monitor and event; unknown monitor or event names are
/// errors naming the key.
fn configure_freeze_frames(
    cfg: &RuntimeConfig,
    table: &SignalTable,
    monitors: &mut [Box<dyn Monitor>],
) -> Result<(), RuntimeError> {
    let ff = &cfg.freeze_frames;
    let invalid = |message: String| {
        RuntimeError::Config(ConfigError::Message {
            origin: cfg.origin.clone(),
            message,
        })
    };
    const KNOWN: [&str; 4] = ["staleness", "throttle", "intake", "ingestion"];
    for name in ff.monitors.keys() {
        if !KNOWN.contains(&name.as_str()) {
            return Err(invalid(format!(
                "invalid `freeze_frames.monitors.{name}`: no such monitor (known: {})",
                KNOWN.join(", ")
            )));
        }
    }
    let mut known_events: Vec<String> = cfg
        .signals
        .iter()
        .map(|s| config::stale_event_name(&s.name))
        .collect();
    known_events.extend(crate::throttle::EVENT_NAMES.iter().map(|s| s.to_string()));
    known_events.extend(crate::intake::EVENT_NAMES.iter().map(|s| s.to_string()));
    for m in monitors.iter() {
        let ev = m.events();
        known_events.extend((0..ev.len()).map(|i| ev.name(i).to_string()));
    }
    for name in ff.events.keys() {
        if !known_events.contains(name) {
            return Err(invalid(format!(
                "invalid `freeze_frames.events.{name}`: no event of that name"
            )));
        }
    }
    for m in monitors.iter_mut() {
        let mname = m.name().to_string();
        let default = match ff.monitors.get(&mname) {
            Some(list) => list.clone(),
            None => m.default_freeze_frame(),
        };
        let ev = m.events();
        let names: Vec<String> = (0..ev.len()).map(|i| ev.name(i).to_string()).collect();
        let lists: Vec<Vec<String>> = names
            .iter()
            .map(|n| ff.events.get(n).cloned().unwrap_or_else(|| default.clone()))
            .collect();
        let key = |i: usize| {
            if ff.events.contains_key(&names[i]) {
                format!("freeze_frames.events.{}", names[i])
            } else if ff.monitors.contains_key(&mname) {
                format!("freeze_frames.monitors.{mname}")
            } else {
                format!("the default freeze frame of monitor `{mname}`")
            }
        };
        m.events_mut()
            .configure_freeze_frames(&lists, table, &key)
            .map_err(|e| invalid(e.to_string()))?;
    }
    Ok(())
}

/// The names of the runtime signals a subsystem monitor (`throttle`, `intake`) reads, as its
/// configuration file names them.
pub fn monitor_inputs(cfg: &RuntimeConfig, monitor: &str) -> Result<Vec<String>, RuntimeError> {
    Ok(match monitor {
        "throttle" => {
            let m = crate::config::ThrottleConfig::load(cfg.monitors.throttle_config.as_deref())?
                .monitor;
            vec![m.motor_voltage_signal, m.tps_signal, m.wattmeter_signal]
        }
        "intake" => {
            let m =
                crate::config::IntakeConfig::load(cfg.monitors.intake_config.as_deref())?.monitor;
            vec![
                m.speed_signal,
                m.throttle_signal,
                m.egr_signal,
                m.map_signal,
                m.maf_signal,
            ]
        }
        "turbo" => {
            let m = crate::turbo::TurboConfig::load(cfg.monitors.turbo_config.as_deref())?.monitor;
            vec![
                m.p_ic_signal,
                m.t_ic_signal,
                m.p_im_signal,
                m.maf_signal,
                m.speed_signal,
                m.throttle_signal,
                m.wastegate_signal,
                m.ambient_pressure_signal,
                m.ambient_temperature_signal,
            ]
        }
        "wheel" => {
            let m = crate::wheel::WheelConfig::load(cfg.monitors.wheel_config.as_deref())?.monitor;
            m.speed_signals
                .into_iter()
                .chain(m.current_signals)
                .chain(m.brake_signals)
                .chain([m.drive_signal])
                .collect()
        }
        other => {
            return Err(RuntimeError::UnknownMonitor(
                other.to_string(),
                "throttle, intake, turbo, wheel".to_string(),
            ))
        }
    })
}

fn throttle_monitor(
    cfg: &RuntimeConfig,
    table: &SignalTable,
) -> Result<crate::throttle::ThrottleMonitor, RuntimeError> {
    let throttle = crate::config::ThrottleConfig::load(cfg.monitors.throttle_config.as_deref())?;
    let err = |message: String| RuntimeError::Monitor {
        origin: cfg.origin.clone(),
        monitor: "throttle".into(),
        message,
    };
    let model =
        fdd_estimators::models::throttle::ThrottleModel::new(throttle.model).map_err(err)?;
    let monitor = crate::throttle::ThrottleMonitor::new(
        model,
        throttle.position_sensor.full_scale_v,
        throttle.position_sensor.full_scale_deg,
        &throttle.monitor,
        table,
    )
    .map_err(|e| err(e.to_string()))?;
    tracing::info!(
        config = cfg
            .monitors
            .throttle_config
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "embedded config/throttle.toml".into()),
        "throttle monitor configured"
    );
    Ok(monitor)
}

fn turbo_monitor(
    cfg: &RuntimeConfig,
    table: &SignalTable,
) -> Result<crate::turbo::TurboMonitor, RuntimeError> {
    let turbo = crate::turbo::TurboConfig::load(cfg.monitors.turbo_config.as_deref())?;
    let monitor = crate::turbo::TurboMonitor::new(&turbo.params, &turbo.monitor, table).map_err(
        |message| RuntimeError::Monitor {
            origin: cfg.origin.clone(),
            monitor: "turbo".into(),
            message,
        },
    )?;
    tracing::info!(
        config = cfg
            .monitors
            .turbo_config
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "embedded config/turbo_monitor.toml".into()),
        params = %turbo.params_origin,
        "turbo monitor configured"
    );
    Ok(monitor)
}

fn wheel_monitor(
    cfg: &RuntimeConfig,
    table: &SignalTable,
) -> Result<crate::wheel::WheelMonitor, RuntimeError> {
    let wheel = crate::wheel::WheelConfig::load(cfg.monitors.wheel_config.as_deref())?;
    let monitor = crate::wheel::WheelMonitor::new(&wheel, table).map_err(|message| {
        RuntimeError::Monitor {
            origin: cfg.origin.clone(),
            monitor: "wheel".into(),
            message,
        }
    })?;
    tracing::info!(
        config = cfg
            .monitors
            .wheel_config
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "embedded config/wheel_monitor.toml".into()),
        params = %wheel.params_origin,
        "wheel monitor configured"
    );
    Ok(monitor)
}

fn intake_monitor(
    cfg: &RuntimeConfig,
    table: &SignalTable,
) -> Result<crate::intake::IntakeMonitor, RuntimeError> {
    let intake = crate::config::IntakeConfig::load(cfg.monitors.intake_config.as_deref())?;
    let err = |message: String| RuntimeError::Monitor {
        origin: cfg.origin.clone(),
        monitor: "intake".into(),
        message,
    };
    let model = fdd_estimators::models::intake::IntakeModel::new(
        intake.model,
        fdd_estimators::models::intake::ThrottleFlow::RandomWalk,
    )
    .map_err(err)?;
    let monitor = crate::intake::IntakeMonitor::new(&model, &intake.monitor, table)
        .map_err(|e| err(e.to_string()))?;
    tracing::info!(
        config = cfg
            .monitors
            .intake_config
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "embedded config/intake.toml".into()),
        "intake monitor configured"
    );
    Ok(monitor)
}
