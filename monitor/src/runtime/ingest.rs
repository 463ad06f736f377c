//! Ring-buffer ingestion: one single-producer / single-consumer queue (`ringbuf`) per
//! producing task of the host (a CAN task, an ADC task), sized at construction. A producer
//! never blocks: when its queue is full the sample is counted as lost (per queue, exactly), and
//! the runtime's `ingestion` monitor raises the queue's "samples lost" event with the count.
//! [`crate::runtime::Runtime::advance_to`] drains every queue in time order.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use fdd_diagnostics::{TestResult, Verdict};
use ringbuf::traits::{Consumer, Observer, Producer, Split};
use ringbuf::{HeapCons, HeapProd, HeapRb};

use crate::monitor::{Monitor, OutputSink};
use crate::monitor_events::{EventSpec, FreezeValues, MonitorEvents};
use crate::signal_table::{SignalId, SignalTable};

/// One sample in a queue.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QueuedSample {
    pub signal: SignalId,
    pub t_ns: u64,
    pub value: f64,
}

/// Counters shared by a producer and the runtime.
#[derive(Debug, Default)]
pub(crate) struct Shared {
    /// Samples refused because the queue was full.
    lost: AtomicU64,
    /// Samples refused because the signal id is not in the table.
    invalid: AtomicU64,
    /// Samples accepted into the queue.
    pushed: AtomicU64,
}

/// The producing end of one queue. `Send`: move it to the task that produces the samples.
pub struct SampleProducer {
    name: Arc<str>,
    prod: HeapProd<QueuedSample>,
    shared: Arc<Shared>,
    signals: usize,
}

impl std::fmt::Debug for SampleProducer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SampleProducer")
            .field("name", &self.name)
            .field("lost", &self.lost())
            .finish()
    }
}

impl SampleProducer {
    /// Queues a sample; never blocks and never allocates. `false` when it was not queued: the
    /// queue was full (counted as lost) or the signal id is not the runtime's (counted as
    /// invalid).
    pub fn push(&mut self, signal: SignalId, t_ns: u64, value: f64) -> bool {
        if signal.index() >= self.signals {
            self.shared.invalid.fetch_add(1, Ordering::Relaxed);
            return false;
        }
        match self.prod.try_push(QueuedSample {
            signal,
            t_ns,
            value,
        }) {
            Ok(()) => {
                self.shared.pushed.fetch_add(1, Ordering::Relaxed);
                true
            }
            Err(_) => {
                self.shared.lost.fetch_add(1, Ordering::Relaxed);
                false
            }
        }
    }

    /// Samples lost so far because the queue was full.
    pub fn lost(&self) -> u64 {
        self.shared.lost.load(Ordering::Relaxed)
    }

    /// The queue's name.
    pub fn name(&self) -> &str {
        &self.name
    }
}

/// What happened to one queue's samples.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct QueueStats {
    pub name: String,
    pub capacity: usize,
    /// Accepted by the queue.
    pub pushed: u64,
    /// Lost because the queue was full.
    pub lost: u64,
    /// Refused by the producer: signal id not in the table.
    pub invalid: u64,
    /// Stored in the signal table.
    pub applied: u64,
    /// Refused by the signal table (non-finite, repeated or backward time stamp).
    pub rejected: u64,
    /// Applied after the runtime's time had passed their time stamp (pushed too late).
    pub late: u64,
}

/// The consuming end, kept by the runtime.
pub(crate) struct Queue {
    name: Arc<str>,
    cons: HeapCons<QueuedSample>,
    shared: Arc<Shared>,
    /// A sample popped but not yet due.
    pub(crate) head: Option<QueuedSample>,
    pub(crate) applied: u64,
    pub(crate) rejected: u64,
    pub(crate) late: u64,
}

impl Queue {
    /// A queue of `capacity` samples (at least 1) and its producer, for a table of `signals`.
    pub(crate) fn new(name: &str, capacity: usize, signals: usize) -> (Queue, SampleProducer) {
        let (prod, cons) = HeapRb::<QueuedSample>::new(capacity.max(1)).split();
        let name: Arc<str> = name.into();
        let shared = Arc::new(Shared::default());
        (
            Queue {
                name: name.clone(),
                cons,
                shared: shared.clone(),
                head: None,
                applied: 0,
                rejected: 0,
                late: 0,
            },
            SampleProducer {
                name,
                prod,
                shared,
                signals,
            },
        )
    }

    /// The next sample, popped into `head` if needed.
    pub(crate) fn peek(&mut self) -> Option<QueuedSample> {
        if self.head.is_none() {
            self.head = self.cons.try_pop();
        }
        self.head
    }

    /// The counters, for the ingestion monitor.
    pub(crate) fn shared(&self) -> Arc<Shared> {
        self.shared.clone()
    }

    /// The queue's name.
    pub(crate) fn name(&self) -> &str {
        &self.name
    }

    pub(crate) fn stats(&self) -> QueueStats {
        QueueStats {
            name: self.name.to_string(),
            capacity: self.cons.capacity().get(),
            pushed: self.shared.pushed.load(Ordering::Relaxed),
            lost: self.shared.lost.load(Ordering::Relaxed),
            invalid: self.shared.invalid.load(Ordering::Relaxed),
            applied: self.applied,
            rejected: self.rejected,
            late: self.late,
        }
    }
}

/// The `ingestion` monitor: one event per queue (`<queue>_samples_lost`), failed when samples
/// were lost since its previous check, with the queue's total lost count as the test value
/// (limit 0), passed otherwise.
pub(crate) struct IngestionMonitor {
    period_ns: u64,
    /// Each queue's counters, and its lost total as of the previous check.
    queues: Vec<Arc<Shared>>,
    seen: Vec<u64>,
    events: MonitorEvents,
}

impl IngestionMonitor {
    pub(crate) const NAME: &'static str = "ingestion";

    /// One event per queue (`<name>_samples_lost` with the queue's DTC).
    pub(crate) fn new(
        queues: &[(&Queue, &str)],
        period_ns: u64,
    ) -> Result<Self, fdd_diagnostics::ConfigError> {
        let names: Vec<String> = queues
            .iter()
            .map(|(q, _)| format!("{}_samples_lost", q.name()))
            .collect();
        let specs: Vec<EventSpec<'_>> = queues
            .iter()
            .zip(&names)
            .map(|((_, dtc), name)| EventSpec::internal(name, dtc, 2))
            .collect();
        Ok(IngestionMonitor {
            period_ns,
            queues: queues.iter().map(|(q, _)| q.shared()).collect(),
            seen: vec![0; queues.len()],
            events: MonitorEvents::with_capacity(&specs, queues.len().max(1))?,
        })
    }
}

impl Monitor for IngestionMonitor {
    fn name(&self) -> &str {
        Self::NAME
    }

    fn period_ns(&self) -> u64 {
        self.period_ns
    }

    fn inputs(&self) -> &[SignalId] {
        &[]
    }

    fn step(&mut self, now_ns: u64, _signals: &SignalTable, out: &mut OutputSink<'_>) {
        for k in 0..self.seen.len() {
            let lost = self.queues[k].lost.load(Ordering::Relaxed);
            let failed = lost > self.seen[k];
            self.seen[k] = lost;
            let result = TestResult {
                value: lost as f64,
                min: 0.0,
                max: 0.0,
                verdict: if failed {
                    Verdict::Failed
                } else {
                    Verdict::Passed
                },
            };
            self.events.report_one(
                k,
                now_ns as f64 * 1e-9,
                &result,
                &[],
                FreezeValues::NONE,
                out,
            );
        }
    }

    fn start_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        self.events.start_operation_cycle(now_ns, out);
    }

    fn end_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        self.events.end_operation_cycle(now_ns, out);
    }

    fn events(&self) -> &MonitorEvents {
        &self.events
    }

    fn events_mut(&mut self) -> &mut MonitorEvents {
        &mut self.events
    }
}
