//! [`StalenessMonitor`]: a lost signal is itself a diagnostic event (failure type byte 0x31,
//! "no signal").
//!
//! Every check period the monitor looks at each configured signal in the [`SignalTable`]:
//!
//! - a signal whose latest sample is older than its `max_age` is **stale**;
//! - a signal that has had no sample at all is **missing** once `max_age` has passed since the
//!   start of the operation cycle (before that it is not tested: the start-up grace period);
//! - otherwise it is fresh.
//!
//! Each signal has one event (`<signal>_no_signal`, DTC from the configuration) in the
//! monitor's own event memory ([`MonitorEvents`]). With the default monitor-internal debounce, stale or missing
//! reports `FAILED` and fresh `PASSED` (the `max_age` is the debounce time); with a counter or
//! time debounce, `PRE_FAILED` / `PRE_PASSED` and the debouncer qualifies. The test result
//! carries the sample's age in seconds (`null` while missing) against `[0, max_age_s]`.
//!
//! Outputs: every status change as [`crate::monitor::Output::Event`], and the new status byte
//! as [`crate::monitor::Output::DtcStatus`]. A signal going stale or missing is logged at `warn` once per episode,
//! its recovery at `info`. A step with no status change allocates nothing and logs nothing.

use fdd_diagnostics::dtc::{DebounceConfig, Dtc};
use fdd_diagnostics::{TestResult, Verdict};

use crate::monitor::{Monitor, OutputSink};
use crate::monitor_events::{EventSpec, FreezeValues, MonitorEvents};
use crate::runtime::config::{s_to_ns, stale_event_name, RuntimeConfig};
use crate::signal_table::{SignalId, SignalTable};

/// What the monitor last saw of a signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Seen {
    /// In the start-up grace period, or fresh.
    Fine,
    /// No sample since the start, past the grace period.
    Missing,
    /// Latest sample older than `max_age`.
    Stale,
}

#[derive(Debug)]
struct Watched {
    id: SignalId,
    /// Index of its event in the memory (= index of the signal in the configuration).
    event: usize,
    dtc: Dtc,
    name: String,
    topic: String,
    max_age_ns: u64,
    seen: Seen,
    /// Whether the signal is watched now (its consumer runs).
    active: bool,
    /// Stale or missing episodes so far.
    episodes: u64,
}

/// Why the staleness monitor could not be built.
#[derive(Debug, thiserror::Error)]
pub enum StalenessError {
    #[error("staleness monitor: signal `{0}` is not in the signal table")]
    MissingSignal(String),
    #[error("staleness monitor: {0}")]
    Events(#[from] fdd_diagnostics::ConfigError),
}

/// The staleness monitor. See the [module documentation](self).
#[derive(Debug)]
pub struct StalenessMonitor {
    period_ns: u64,
    inputs: Vec<SignalId>,
    watched: Vec<Watched>,
    events: MonitorEvents,
    internal_debounce: bool,
    cycle_start_ns: u64,
}

impl StalenessMonitor {
    /// Name used in logs and summaries.
    pub const NAME: &'static str = "staleness";

    /// One event per configured signal, resolved against `table`. The signals named in
    /// `watch` are watched (the inputs of the monitors that run); the others keep their event
    /// but are never tested until [`StalenessMonitor::set_watched`] says so.
    pub fn from_config(
        cfg: &RuntimeConfig,
        table: &SignalTable,
        watch: &[SignalId],
    ) -> Result<Self, StalenessError> {
        let names: Vec<String> = cfg
            .signals
            .iter()
            .map(|s| stale_event_name(&s.name))
            .collect();
        let specs: Vec<EventSpec<'_>> = cfg
            .signals
            .iter()
            .zip(&names)
            .map(|(s, name)| EventSpec {
                name,
                dtc: &s.stale_dtc,
                priority: cfg.staleness.priority,
                debounce: cfg.staleness.debounce,
                mil: true,
            })
            .collect();
        let events = MonitorEvents::with_capacity(&specs, cfg.signals.len().max(1))?;
        let mut watched = Vec::with_capacity(cfg.signals.len());
        for (i, s) in cfg.signals.iter().enumerate() {
            let id = table
                .id(&s.name)
                .ok_or_else(|| StalenessError::MissingSignal(s.name.clone()))?;
            watched.push(Watched {
                id,
                event: i,
                dtc: events.dtc(i),
                name: s.name.clone(),
                topic: s.topic.clone(),
                max_age_ns: table.spec(id).max_age_ns,
                seen: Seen::Fine,
                active: watch.contains(&id),
                episodes: 0,
            });
        }
        Ok(StalenessMonitor {
            period_ns: s_to_ns(cfg.staleness.check_period_s),
            inputs: watched.iter().filter(|w| w.active).map(|w| w.id).collect(),
            watched,
            events,
            internal_debounce: cfg.staleness.debounce == DebounceConfig::MonitorInternal,
            cycle_start_ns: 0,
        })
    }

    /// Starts or stops watching a signal (its consumer was enabled or disabled). A signal
    /// that is not watched is not tested: its "no signal" event keeps its status.
    pub fn set_watched(&mut self, id: SignalId, on: bool) {
        for w in self.watched.iter_mut().filter(|w| w.id == id) {
            w.active = on;
            w.seen = Seen::Fine;
        }
        self.inputs = self
            .watched
            .iter()
            .filter(|w| w.active)
            .map(|w| w.id)
            .collect();
    }

    /// Stale or missing episodes of a signal so far.
    pub fn episodes(&self, id: SignalId) -> u64 {
        self.watched
            .iter()
            .filter(|w| w.id == id)
            .map(|w| w.episodes)
            .sum()
    }
}

impl Monitor for StalenessMonitor {
    fn name(&self) -> &str {
        Self::NAME
    }

    fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// The watched signals.
    fn inputs(&self) -> &[SignalId] {
        &self.inputs
    }

    fn step(&mut self, now_ns: u64, signals: &SignalTable, out: &mut OutputSink<'_>) {
        for k in 0..self.watched.len() {
            let w = &self.watched[k];
            if !w.active {
                continue;
            }
            let max_age_s = w.max_age_ns as f64 * 1e-9;
            let (seen, age_s) = match signals.try_get(w.id) {
                None => {
                    let since_start = now_ns.saturating_sub(self.cycle_start_ns);
                    if since_start > w.max_age_ns {
                        (Seen::Missing, f64::NAN)
                    } else {
                        // Start-up grace period: no evidence either way.
                        continue;
                    }
                }
                Some(s) => {
                    let age_s = now_ns.saturating_sub(s.t_ns) as f64 * 1e-9;
                    if signals.is_stale(w.id, now_ns) {
                        (Seen::Stale, age_s)
                    } else {
                        (Seen::Fine, age_s)
                    }
                }
            };
            let failing = seen != Seen::Fine;
            if seen != w.seen {
                let t_s = now_ns as f64 * 1e-9;
                match seen {
                    Seen::Missing => tracing::warn!(
                        signal = %w.name,
                        topic = %w.topic,
                        "signal missing: no sample on {} in the first {:.3} s of the operation cycle (at {t_s:.6} s); {} 'no signal' test fails",
                        w.topic,
                        max_age_s,
                        w.dtc
                    ),
                    Seen::Stale => tracing::warn!(
                        signal = %w.name,
                        topic = %w.topic,
                        "signal stale: latest sample on {} is {:.6} s old at {t_s:.6} s (max age {max_age_s} s); {} 'no signal' test fails",
                        w.topic,
                        age_s,
                        w.dtc
                    ),
                    Seen::Fine => tracing::info!(
                        signal = %w.name,
                        topic = %w.topic,
                        "signal back at {t_s:.6} s"
                    ),
                }
                let w = &mut self.watched[k];
                if failing {
                    w.episodes += 1;
                }
                w.seen = seen;
            }
            let verdict = match (failing, self.internal_debounce) {
                (true, true) => Verdict::Failed,
                (true, false) => Verdict::PreFailed,
                (false, true) => Verdict::Passed,
                (false, false) => Verdict::PrePassed,
            };
            let result = TestResult {
                value: age_s,
                min: 0.0,
                max: max_age_s,
                verdict,
            };
            let values = FreezeValues {
                signals: Some(signals),
                estimates: &[],
            };
            let event = self.watched[k].event;
            self.events
                .report_one(event, now_ns as f64 * 1e-9, &result, &[], values, out);
        }
    }

    fn start_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        self.cycle_start_ns = now_ns;
        for w in &mut self.watched {
            w.seen = Seen::Fine;
        }
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

    fn set_signal_watched(&mut self, id: SignalId, watched: bool) {
        self.set_watched(id, watched);
    }

    /// Every watched signal's latest value.
    fn default_freeze_frame(&self) -> Vec<String> {
        self.watched
            .iter()
            .filter(|w| w.active)
            .map(|w| w.name.clone())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::monitor::Output;
    use fdd_diagnostics::dtc::StatusBit;
    use fdd_diagnostics::event::DiagnosticEvent;

    fn setup() -> (RuntimeConfig, SignalTable, StalenessMonitor) {
        let cfg = RuntimeConfig::load(None).expect("embedded");
        let table = cfg.signal_table().expect("table");
        let all: Vec<SignalId> = table.ids().collect();
        let m = StalenessMonitor::from_config(&cfg, &table, &all).expect("monitor");
        (cfg, table, m)
    }

    #[test]
    fn missing_signal_fails_after_grace_and_fresh_ones_pass() {
        let (_, mut table, mut m) = setup();
        let mv = table.id("motor_voltage").unwrap();
        let tps = table.id("tps").unwrap();
        let mut events: Vec<DiagnosticEvent> = Vec::new();
        let mut sink = |o: Output<'_>| {
            if let Output::Event(e) = o {
                events.push(e.to_event());
            }
        };
        m.start_operation_cycle(0, &mut sink);
        for k in 0..10u64 {
            let t = k * 1_000_000;
            table.set(mv, t, 1.0).unwrap();
            table.set(tps, t, 1.0).unwrap();
            m.step(t, &table, &mut sink);
        }
        let failed: Vec<_> = events
            .iter()
            .filter(|e| e.bit_changed(StatusBit::TestFailed) && e.status_after.test_failed())
            .collect();
        assert_eq!(failed.len(), 1, "{events:#?}");
        assert_eq!(failed[0].event, "wattmeter_no_signal");
        assert_eq!(failed[0].dtc.ftb, 0x31);
        // Past the 5 ms grace: the first step at 6 ms.
        assert!((failed[0].time_s - 0.006).abs() < 1e-12);
        assert_eq!(m.episodes(table.id("wattmeter").unwrap()), 1);
    }

    #[test]
    fn stale_then_back() {
        let (_, mut table, mut m) = setup();
        let mut raised = Vec::new();
        let mut sink = |o: Output<'_>| {
            if let Output::Event(e) = o {
                if e.bit_changed(StatusBit::TestFailed) {
                    raised.push((e.event.to_string(), e.time_s, e.status_after.test_failed()));
                }
            }
        };
        m.start_operation_cycle(0, &mut sink);
        let ids: Vec<_> = table.ids().collect();
        for k in 0..40u64 {
            let t = k * 1_000_000;
            for &id in &ids {
                // tps silent from 10 to 20 ms.
                if id.index() == 1 && (10..20).contains(&k) {
                    continue;
                }
                table.set(id, t, 1.0).unwrap();
            }
            m.step(t, &table, &mut sink);
        }
        assert_eq!(raised.len(), 2, "{raised:?}");
        assert_eq!(raised[0].0, "tps_no_signal");
        assert!(raised[0].2);
        // Last sample at 9 ms; stale when older than 5 ms: at 15 ms.
        assert!((raised[0].1 - 0.015).abs() < 1e-12, "{raised:?}");
        assert!(!raised[1].2);
        assert!((raised[1].1 - 0.020).abs() < 1e-12, "{raised:?}");
    }
}
