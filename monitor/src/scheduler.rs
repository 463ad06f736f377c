//! Steps each monitor at its own rate as time advances.
//!
//! Time is whatever the host says it is (bus time, or the log time of a replay): the scheduler
//! has no clock. Before the host applies a sample stamped `t`, it calls
//! [`Scheduler::run_until`]`(t)`, which runs every step due strictly before `t`, in time order
//! across monitors, on the table as it was; a step due exactly at `t` runs after that sample.
//! So a step at time `T` sees exactly the samples stamped `<= T`.

use crate::monitor::{Monitor, Output};
use crate::signal_table::SignalTable;

struct Entry {
    monitor: Box<dyn Monitor>,
    period_ns: u64,
    next_due_ns: u64,
    steps: u64,
    enabled: bool,
}

/// Why a monitor could not be scheduled.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ScheduleError {
    #[error("monitor `{0}` has a period of 0 ns")]
    ZeroPeriod(String),
}

/// The sink of a scheduled step: the monitor's index, the step's time (ns) and the output.
pub type StepSink<'s> = dyn FnMut(usize, u64, Output<'_>) + 's;

/// The set of monitors and when each runs next.
pub struct Scheduler {
    entries: Vec<Entry>,
    start_ns: u64,
    /// Whether innovations and test statistics are passed on (see [`Scheduler::set_detail`]).
    detail: bool,
}

impl Scheduler {
    /// An empty scheduler whose first steps fall at `start_ns`.
    pub fn new(start_ns: u64) -> Self {
        Self {
            entries: Vec::new(),
            start_ns,
            detail: true,
        }
    }

    /// Adds a monitor (enabled); its first step is due at the scheduler's start time. Returns
    /// its index.
    pub fn add(&mut self, monitor: Box<dyn Monitor>) -> Result<usize, ScheduleError> {
        let period_ns = monitor.period_ns();
        if period_ns == 0 {
            return Err(ScheduleError::ZeroPeriod(monitor.name().to_string()));
        }
        self.entries.push(Entry {
            monitor,
            period_ns,
            next_due_ns: self.start_ns,
            steps: 0,
            enabled: true,
        });
        Ok(self.entries.len() - 1)
    }

    /// Number of monitors.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True without monitors.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Monitor `i`.
    pub fn monitor(&self, i: usize) -> &dyn Monitor {
        self.entries[i].monitor.as_ref()
    }

    /// Monitor `i`, mutably.
    pub fn monitor_mut(&mut self, i: usize) -> &mut dyn Monitor {
        self.entries[i].monitor.as_mut()
    }

    /// The monitors, in the order they were added.
    pub fn monitors(&self) -> impl Iterator<Item = &dyn Monitor> {
        self.entries.iter().map(|e| e.monitor.as_ref())
    }

    /// Whether monitor `i` is stepped.
    pub fn enabled(&self, i: usize) -> bool {
        self.entries[i].enabled
    }

    /// Enables or disables monitor `i`. A monitor enabled again resumes at its next due time
    /// after the latest step of any monitor (it does not catch up on the steps it missed).
    pub fn set_enabled(&mut self, i: usize, on: bool, now_ns: u64) {
        let e = &mut self.entries[i];
        if on && !e.enabled && e.next_due_ns <= now_ns {
            // The first due time after `now_ns` on the monitor's grid, in one step (a monitor
            // disabled for hours would otherwise take millions of additions).
            let missed = (now_ns - e.next_due_ns) / e.period_ns + 1;
            e.next_due_ns = e
                .next_due_ns
                .saturating_add(missed.saturating_mul(e.period_ns));
        }
        e.enabled = on;
    }

    /// Whether the steps' innovations, test statistics and diagnoses reach the sink (default
    /// true). A host that only wants events, status bytes and estimates turns them off, and
    /// the outputs of a step stop at the monitor's own callback.
    pub fn set_detail(&mut self, on: bool) {
        self.detail = on;
    }

    /// Every monitor's next step falls at `start_ns` again (a new operation cycle).
    pub fn restart(&mut self, start_ns: u64) {
        self.start_ns = start_ns;
        for e in &mut self.entries {
            e.next_due_ns = start_ns;
        }
    }

    /// Runs every step due strictly before `t_ns`, earliest first (ties in the order the
    /// monitors were added). Returns the number of steps run.
    pub fn run_until(&mut self, t_ns: u64, signals: &SignalTable, out: &mut StepSink<'_>) -> u64 {
        let mut ran = 0;
        loop {
            let mut next: Option<(usize, u64)> = None;
            for (i, e) in self.entries.iter().enumerate() {
                if e.enabled && e.next_due_ns < t_ns && next.is_none_or(|(_, d)| e.next_due_ns < d)
                {
                    next = Some((i, e.next_due_ns));
                }
            }
            let Some((i, due)) = next else {
                return ran;
            };
            let e = &mut self.entries[i];
            if self.detail {
                e.monitor.step(due, signals, &mut |o| out(i, due, o));
            } else {
                e.monitor.step(due, signals, &mut |o| {
                    if !matches!(
                        o,
                        Output::Innovation { .. } | Output::Test { .. } | Output::Diagnosis { .. }
                    ) {
                        out(i, due, o)
                    }
                });
            }
            e.next_due_ns = due.saturating_add(e.period_ns);
            e.steps += 1;
            ran += 1;
        }
    }

    /// Starts an operation cycle in every monitor (its steps are not rescheduled: see
    /// [`Scheduler::restart`]).
    pub fn start_operation_cycle(&mut self, now_ns: u64, out: &mut StepSink<'_>) {
        for (i, e) in self.entries.iter_mut().enumerate() {
            e.monitor
                .start_operation_cycle(now_ns, &mut |o| out(i, now_ns, o));
        }
    }

    /// Ends the operation cycle in every monitor.
    pub fn end_operation_cycle(&mut self, now_ns: u64, out: &mut StepSink<'_>) {
        for (i, e) in self.entries.iter_mut().enumerate() {
            e.monitor
                .end_operation_cycle(now_ns, &mut |o| out(i, now_ns, o));
        }
    }

    /// `(name, steps run)` per monitor.
    pub fn step_counts(&self) -> impl Iterator<Item = (&str, u64)> {
        self.entries.iter().map(|e| (e.monitor.name(), e.steps))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::monitor::OutputSink;
    use crate::monitor_events::MonitorEvents;
    use crate::signal_table::{SignalId, SignalSpec};
    use std::cell::RefCell;
    use std::rc::Rc;

    /// (monitor, step time, value it saw), shared between the probes and the test.
    type Seen = Rc<RefCell<Vec<(&'static str, u64, Option<f64>)>>>;

    /// Records what each step saw.
    struct Probe {
        name: &'static str,
        period: u64,
        input: SignalId,
        seen: Seen,
        events: MonitorEvents,
    }

    impl Monitor for Probe {
        fn name(&self) -> &str {
            self.name
        }
        fn period_ns(&self) -> u64 {
            self.period
        }
        fn inputs(&self) -> &[SignalId] {
            std::slice::from_ref(&self.input)
        }
        fn step(&mut self, now_ns: u64, signals: &SignalTable, _out: &mut OutputSink<'_>) {
            let v = signals.get(self.input).map(|s| s.value);
            self.seen.borrow_mut().push((self.name, now_ns, v));
        }
        fn start_operation_cycle(&mut self, _now_ns: u64, _out: &mut OutputSink<'_>) {}
        fn end_operation_cycle(&mut self, _now_ns: u64, _out: &mut OutputSink<'_>) {}
        fn events(&self) -> &MonitorEvents {
            &self.events
        }
        fn events_mut(&mut self) -> &mut MonitorEvents {
            &mut self.events
        }
    }

    #[test]
    fn steps_in_time_order_and_see_samples_up_to_their_time() {
        let mut table = SignalTable::new(vec![SignalSpec {
            name: "x".into(),
            max_age_ns: 100,
        }])
        .expect("valid");
        let x = table.id("x").expect("declared");
        let seen = Rc::new(RefCell::new(Vec::new()));
        let mut s = Scheduler::new(0);
        for (name, period) in [("fast", 10), ("slow", 25)] {
            s.add(Box::new(Probe {
                name,
                period,
                input: x,
                seen: seen.clone(),
                events: MonitorEvents::new(&[]).expect("empty"),
            }))
            .expect("valid period");
        }
        let mut sink = |_: usize, _: u64, _: Output<'_>| {};
        // Samples at 0, 10, 20, 30 with values 0, 1, 2, 3.
        for (k, t) in [0u64, 10, 20, 30].into_iter().enumerate() {
            s.run_until(t, &table, &mut sink);
            table.set(x, t, k as f64).expect("increasing");
        }
        s.run_until(31, &table, &mut sink);
        let seen = seen.borrow();
        let expected = vec![
            ("fast", 0, Some(0.0)),
            ("slow", 0, Some(0.0)),
            ("fast", 10, Some(1.0)),
            ("fast", 20, Some(2.0)),
            ("slow", 25, Some(2.0)),
            ("fast", 30, Some(3.0)),
        ];
        assert_eq!(*seen, expected);
        let counts: Vec<_> = s.step_counts().collect();
        assert_eq!(counts, vec![("fast", 4), ("slow", 2)]);
    }

    #[test]
    fn a_monitor_enabled_again_resumes_on_its_grid_without_catching_up() {
        let table = SignalTable::new(vec![SignalSpec {
            name: "x".into(),
            max_age_ns: 100,
        }])
        .expect("valid");
        let seen = Rc::new(RefCell::new(Vec::new()));
        let mut s = Scheduler::new(0);
        s.add(Box::new(Probe {
            name: "m",
            period: 10,
            input: table.id("x").expect("declared"),
            seen: seen.clone(),
            events: MonitorEvents::new(&[]).expect("empty"),
        }))
        .expect("valid period");
        let mut sink = |_: usize, _: u64, _: Output<'_>| {};
        s.run_until(15, &table, &mut sink);
        s.set_enabled(0, false, 15);
        s.run_until(1_000_000_000, &table, &mut sink);
        s.set_enabled(0, true, 1_000_000_005);
        s.run_until(1_000_000_031, &table, &mut sink);
        let times: Vec<u64> = seen.borrow().iter().map(|x| x.1).collect();
        assert_eq!(times, [0, 10, 1_000_000_010, 1_000_000_020, 1_000_000_030]);
    }

    #[test]
    fn zero_period_is_refused() {
        let table = SignalTable::new(vec![SignalSpec {
            name: "x".into(),
            max_age_ns: 1,
        }])
        .expect("valid");
        let mut s = Scheduler::new(0);
        let err = s
            .add(Box::new(Probe {
                name: "bad",
                period: 0,
                input: table.id("x").expect("declared"),
                seen: Rc::new(RefCell::new(Vec::new())),
                events: MonitorEvents::new(&[]).expect("empty"),
            }))
            .unwrap_err();
        assert_eq!(err, ScheduleError::ZeroPeriod("bad".into()));
    }
}
