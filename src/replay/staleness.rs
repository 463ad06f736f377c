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
//! monitor's own [`EventMemory`]. With the default monitor-internal debounce, stale or missing
//! reports `FAILED` and fresh `PASSED` (the `max_age` is the debounce time); with a counter or
//! time debounce, `PRE_FAILED` / `PRE_PASSED` and the debouncer qualifies. The test result
//! carries the sample's age in seconds (`null` while missing) against `[0, max_age_s]`.
//!
//! Outputs: every status change as [`Output::Event`], and the new status byte as
//! [`Output::DtcStatus`]. A signal going stale or missing is logged at `warn` once per episode,
//! its recovery at `info`. A step with no status change allocates nothing and logs nothing.

use fdd_diagnostics::dtc::{DebounceConfig, Dtc, EventId, EventMemory, ReportContext};
use fdd_diagnostics::{TestResult, Verdict};
use fdd_monitor::monitor::{Monitor, Output, OutputSink};
use fdd_monitor::signal_table::{SignalId, SignalTable};

use super::config::{s_to_ns, RuntimeConfig};
use super::ReplayError;

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
    event: EventId,
    dtc: Dtc,
    name: String,
    topic: String,
    max_age_ns: u64,
    seen: Seen,
    /// Stale or missing episodes so far.
    episodes: u64,
}

/// The staleness monitor. See the [module documentation](self).
#[derive(Debug)]
pub struct StalenessMonitor {
    period_ns: u64,
    inputs: Vec<SignalId>,
    watched: Vec<Watched>,
    memory: EventMemory,
    internal_debounce: bool,
    cycle_start_ns: u64,
}

impl StalenessMonitor {
    /// Name used in logs and summaries.
    pub const NAME: &'static str = "staleness";

    /// One event per configured signal, resolved against `table`.
    /// Watches every configured signal except those named in `skip` (the inputs of subsystem
    /// monitors that do not run on this log).
    pub fn from_config(
        cfg: &RuntimeConfig,
        table: &SignalTable,
        skip: &[String],
    ) -> Result<Self, ReplayError> {
        let memory =
            EventMemory::new(&cfg.staleness_memory_config()).map_err(|e| ReplayError::Monitor {
                monitor: Self::NAME.into(),
                message: e.to_string(),
            })?;
        let mut watched = Vec::with_capacity(cfg.signals.len());
        for (i, s) in cfg.signals.iter().enumerate() {
            if skip.contains(&s.name) {
                continue;
            }
            let id = table.id(&s.name).ok_or_else(|| ReplayError::Monitor {
                monitor: Self::NAME.into(),
                message: format!("signal `{}` is not in the signal table", s.name),
            })?;
            let event = memory.event_id_at(i).ok_or_else(|| ReplayError::Monitor {
                monitor: Self::NAME.into(),
                message: format!("no event for signal `{}`", s.name),
            })?;
            watched.push(Watched {
                id,
                event,
                dtc: memory.dtc(event),
                name: s.name.clone(),
                topic: s.topic.clone(),
                max_age_ns: table.spec(id).max_age_ns,
                seen: Seen::Fine,
                episodes: 0,
            });
        }
        Ok(StalenessMonitor {
            period_ns: s_to_ns(cfg.staleness.check_period_s),
            inputs: watched.iter().map(|w| w.id).collect(),
            watched,
            memory,
            internal_debounce: cfg.staleness.debounce == DebounceConfig::MonitorInternal,
            cycle_start_ns: 0,
        })
    }

    fn report(&mut self, k: usize, result: TestResult, now_ns: u64, out: &mut OutputSink<'_>) {
        let w = &self.watched[k];
        let before = self.memory.status(w.event);
        let ctx = ReportContext::at(now_ns as f64 * 1e-9);
        let res = self
            .memory
            .report(w.event, &result, &ctx, |ev| out(Output::Event(&ev)));
        match res {
            Ok(after) if after != before => out(Output::DtcStatus {
                dtc: w.dtc,
                status: after,
            }),
            Ok(_) => {}
            Err(e) => tracing::error!(
                monitor = Self::NAME,
                signal = %w.name,
                "event memory refused a report: {e}"
            ),
        }
    }
}

impl Monitor for StalenessMonitor {
    fn name(&self) -> &str {
        Self::NAME
    }

    fn period_ns(&self) -> u64 {
        self.period_ns
    }

    fn inputs(&self) -> &[SignalId] {
        &self.inputs
    }

    fn step(&mut self, now_ns: u64, signals: &SignalTable, out: &mut OutputSink<'_>) {
        for k in 0..self.watched.len() {
            let w = &self.watched[k];
            let max_age_s = w.max_age_ns as f64 * 1e-9;
            let (seen, age_s) = match signals.get(w.id) {
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
            self.report(k, result, now_ns, out);
        }
    }

    fn start_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        self.cycle_start_ns = now_ns;
        for w in &mut self.watched {
            w.seen = Seen::Fine;
        }
        let before: Vec<_> = self
            .watched
            .iter()
            .map(|w| self.memory.status(w.event))
            .collect();
        if let Err(e) = self
            .memory
            .start_operation_cycle(now_ns as f64 * 1e-9, |ev| out(Output::Event(&ev)))
        {
            tracing::error!(
                monitor = Self::NAME,
                "cannot start the operation cycle: {e}"
            );
        }
        self.emit_status_changes(&before, out);
    }

    fn end_operation_cycle(&mut self, now_ns: u64, out: &mut OutputSink<'_>) {
        let before: Vec<_> = self
            .watched
            .iter()
            .map(|w| self.memory.status(w.event))
            .collect();
        if let Err(e) = self
            .memory
            .end_operation_cycle(now_ns as f64 * 1e-9, |ev| out(Output::Event(&ev)))
        {
            tracing::error!(monitor = Self::NAME, "cannot end the operation cycle: {e}");
        }
        self.emit_status_changes(&before, out);
    }
}

impl StalenessMonitor {
    fn emit_status_changes(
        &self,
        before: &[fdd_diagnostics::dtc::DtcStatus],
        out: &mut OutputSink<'_>,
    ) {
        for (w, b) in self.watched.iter().zip(before) {
            let after = self.memory.status(w.event);
            if after != *b {
                out(Output::DtcStatus {
                    dtc: w.dtc,
                    status: after,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fdd_diagnostics::dtc::StatusBit;
    use fdd_diagnostics::event::DiagnosticEvent;

    fn setup() -> (RuntimeConfig, SignalTable, StalenessMonitor) {
        let cfg = RuntimeConfig::load(None).expect("embedded");
        let table = cfg.signal_table().expect("table");
        let m = StalenessMonitor::from_config(&cfg, &table, &[]).expect("monitor");
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
                events.push(e.clone());
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
        assert_eq!(m.watched[2].episodes, 1);
    }

    #[test]
    fn stale_then_back() {
        let (_, mut table, mut m) = setup();
        let mut raised = Vec::new();
        let mut sink = |o: Output<'_>| {
            if let Output::Event(e) = o {
                if e.bit_changed(StatusBit::TestFailed) {
                    raised.push((e.event.clone(), e.time_s, e.status_after.test_failed()));
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
