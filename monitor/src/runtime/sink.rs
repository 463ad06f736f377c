//! Where the runtime's outputs go: a [`Sink`] the host supplies (any `FnMut(Stamped)` closure
//! is one), or an [`EventQueue`], a bounded queue of fixed-size event records the host drains
//! when it likes. Neither allocates per output.

use fdd_diagnostics::dtc::{Dtc, DtcCode, DtcStatus};
use fdd_diagnostics::event::{EventView, MemoryAction, Trigger};
use fdd_diagnostics::TestResult;

use crate::monitor::Output;

/// One output with the time of the step that produced it and the monitor's name.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stamped<'a> {
    /// Time of the step (or of the operation-cycle / clear call), ns of the host's clock.
    pub t_ns: u64,
    /// The monitor's name (`throttle`, `intake`, `staleness`, `ingestion`).
    pub monitor: &'a str,
    /// What it reported.
    pub output: Output<'a>,
}

/// The host's receiver of outputs. Called from inside [`crate::runtime::Runtime::advance_to`]
/// and the cycle and clear calls; it must not block.
pub trait Sink {
    /// Takes one output.
    fn output(&mut self, o: Stamped<'_>);
}

impl<F: FnMut(Stamped<'_>)> Sink for F {
    fn output(&mut self, o: Stamped<'_>) {
        self(o)
    }
}

/// A sink that drops everything (the event memory still keeps the DTCs).
#[derive(Debug, Default, Clone, Copy)]
pub struct NullSink;

impl Sink for NullSink {
    fn output(&mut self, _o: Stamped<'_>) {}
}

/// The fixed part of a DTC status change: what a C host or a queue can hold without
/// allocating. The event's name, freeze frame and extended data are in the runtime's memory
/// ([`crate::runtime::Runtime::event_name`], [`crate::runtime::Runtime::freeze_frame`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EventRecord {
    /// Time of the change, ns.
    pub t_ns: u64,
    /// Time of the change as the event memory saw it, s.
    pub time_s: f64,
    /// The DTC.
    pub dtc: Dtc,
    /// What caused it.
    pub trigger: Trigger,
    /// ISO 14229-1 status byte before and after.
    pub status_before: DtcStatus,
    pub status_after: DtcStatus,
    /// Fault detection counter after the change.
    pub fdc: i8,
    /// Occurrence and aging counters after the change.
    pub occurrence_counter: u8,
    pub aging_counter: u8,
    /// What happened to the memory entry.
    pub memory: MemoryAction,
    /// The test result that caused it, if a report did.
    pub test_result: Option<TestResult>,
}

impl EventRecord {
    /// The record of an event view emitted at `t_ns`.
    pub fn from_view(t_ns: u64, v: &EventView<'_>) -> Self {
        EventRecord {
            t_ns,
            time_s: v.time_s,
            dtc: v.dtc,
            trigger: v.trigger,
            status_before: v.status_before,
            status_after: v.status_after,
            fdc: v.fdc,
            occurrence_counter: v.occurrence_counter,
            aging_counter: v.aging_counter,
            memory: v.memory,
            test_result: v.test_result,
        }
    }

    /// True when this change set testFailed (a new qualified failure).
    pub fn raised(&self) -> bool {
        !self.status_before.test_failed() && self.status_after.test_failed()
    }
}

/// The latest value of one estimate (e.g. the throttle position and where it comes from).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimateRecord {
    /// Time of the step, ns.
    pub t_ns: u64,
    /// Estimate name (`throttle_angle`, `manifold_pressure`, ...).
    pub name: &'static str,
    /// Value and 95 % interval, in the estimate's unit.
    pub value: f64,
    pub lower: f64,
    pub upper: f64,
    /// Where it comes from (`tps`, `wattmeter_estimate`, `map_local_ekf`, ...).
    pub source: &'static str,
}

/// A bounded queue of [`EventRecord`]s and the latest value of each estimate, filled as a
/// [`Sink`] and drained by the host. Sized at construction; when full, further records are
/// counted in [`EventQueue::dropped`] (never lost silently), and the DTCs themselves stay in
/// the event memory.
#[derive(Debug, Clone)]
pub struct EventQueue {
    buf: Vec<EventRecord>,
    head: usize,
    len: usize,
    dropped: u64,
    estimates: Vec<EstimateRecord>,
    estimates_cap: usize,
}

impl EventQueue {
    /// A queue of `capacity` event records (at least 1) and up to 16 estimates.
    pub fn new(capacity: usize) -> Self {
        let capacity = capacity.max(1);
        let blank = EventRecord {
            t_ns: 0,
            time_s: 0.0,
            dtc: Dtc::new(DtcCode::from_u16(0), 0),
            trigger: Trigger::TestResult,
            status_before: DtcStatus::default(),
            status_after: DtcStatus::default(),
            fdc: 0,
            occurrence_counter: 0,
            aging_counter: 0,
            memory: MemoryAction::Unchanged,
            test_result: None,
        };
        EventQueue {
            buf: vec![blank; capacity],
            head: 0,
            len: 0,
            dropped: 0,
            estimates: Vec::with_capacity(16),
            estimates_cap: 16,
        }
    }

    /// Records waiting.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when no record waits.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Records that did not fit since construction.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// The oldest waiting record.
    pub fn pop(&mut self) -> Option<EventRecord> {
        if self.len == 0 {
            return None;
        }
        let r = self.buf[self.head];
        self.head = (self.head + 1) % self.buf.len();
        self.len -= 1;
        Some(r)
    }

    /// The latest value of the estimate `name`, if one was reported.
    pub fn estimate(&self, name: &str) -> Option<&EstimateRecord> {
        self.estimates.iter().find(|e| e.name == name)
    }

    /// The latest value of every estimate reported so far.
    pub fn estimates(&self) -> &[EstimateRecord] {
        &self.estimates
    }

    fn push(&mut self, r: EventRecord) {
        if self.len == self.buf.len() {
            self.dropped += 1;
            return;
        }
        let k = (self.head + self.len) % self.buf.len();
        self.buf[k] = r;
        self.len += 1;
    }
}

impl Sink for EventQueue {
    fn output(&mut self, o: Stamped<'_>) {
        match o.output {
            Output::Event(v) => self.push(EventRecord::from_view(o.t_ns, v)),
            Output::Estimate {
                name,
                value,
                lower,
                upper,
                source,
            } => {
                let rec = EstimateRecord {
                    t_ns: o.t_ns,
                    name,
                    value,
                    lower,
                    upper,
                    source,
                };
                if let Some(e) = self.estimates.iter_mut().find(|e| e.name == name) {
                    *e = rec;
                } else if self.estimates.len() < self.estimates_cap {
                    self.estimates.push(rec);
                }
            }
            _ => {}
        }
    }
}
