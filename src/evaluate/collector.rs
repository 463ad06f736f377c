//! The evaluation's view of a replay: per monitor step, the monitor's diagnosis
//! ([`Output::Diagnosis`]) against the ground truth of the log at that time; per raised DTC,
//! whether it names the fault present. Fed by the replay's sink ([`crate::replay`]) and kept
//! across logs, so that one [`Evaluator`] per monitor sees every log.

use std::collections::BTreeMap;

use fdd_diagnostics::evaluation::{DtcKind, EvaluationReport, Evaluator, Truth};
use fdd_diagnostics::event::EventView;
use fdd_monitor::monitor::Output;
use fdd_monitor::runtime::config::TruthConfig;
use fdd_monitor::runtime::Runtime;

use crate::replay::ReplayObserver;

use super::fault_types::{fault_types, group_events, FaultType};

/// The latest ground truth of one truth topic.
#[derive(Debug, Clone, Default)]
struct TruthState {
    /// A truth message has been seen in this log.
    seen: bool,
    active: bool,
    observable: bool,
    fault: String,
    /// When the last fault ended (active -> inactive), ns.
    ended_ns: Option<u64>,
}

/// After a fault ends, this long (s) counts nowhere: a monitor needs evidence that a fault is
/// gone before its test passes again (the throttle monitor's `heal_s` is 5 s), so flags in it
/// are neither false alarms nor detections.
pub const HEAL_GRACE_S: f64 = 10.0;

/// One monitor's evaluation.
#[derive(Debug, Clone)]
struct MonitorEvaluation {
    monitor: String,
    /// Index of its truth topic in the configuration's `[[truth]]` (the one whose estimate the
    /// monitor outputs), in the current log.
    truth: Option<usize>,
    types: &'static [FaultType],
    /// Per fault type, the indices of the monitor's diagnosis classes scored as it.
    scored_as: Vec<Vec<usize>>,
    evaluator: Evaluator,
}

/// Evaluation state kept across the logs of one `fdd evaluate`.
#[derive(Debug, Clone, Default)]
pub struct Evaluation {
    monitors: Vec<MonitorEvaluation>,
    truths: Vec<TruthState>,
    scores: Vec<f64>,
    classes: Vec<usize>,
    /// Truth fault names that are not in the fault-type table, with the samples they made
    /// uncounted.
    pub unknown_faults: BTreeMap<String, u64>,
    /// Samples or DTCs the evaluator refused (a monitor's score outside [0, 1], time going
    /// backwards), with the first message.
    pub refused: u64,
    pub first_refusal: Option<String>,
}

impl ReplayObserver for Evaluation {
    fn begin_log(&mut self, rt: &Runtime, truths: &[TruthConfig]) {
        Evaluation::begin_log(self, rt, truths);
    }

    fn output(&mut self, t_ns: u64, monitor: &str, output: &Output<'_>) {
        match *output {
            Output::Diagnosis { flagged, scores } => self.diagnosis(t_ns, monitor, flagged, scores),
            Output::Event(ev) => self.event(t_ns, monitor, ev),
            _ => {}
        }
    }

    fn truth(
        &mut self,
        t_ns: u64,
        index: usize,
        fault: &str,
        active: bool,
        observable: Option<bool>,
    ) {
        Evaluation::truth(self, t_ns, index, fault, active, observable);
    }

    fn end_log(&mut self) {
        Evaluation::end_log(self);
    }
}

impl Evaluation {
    /// A new log replayed by `rt`, with the configuration's truth topics.
    pub fn begin_log(&mut self, rt: &Runtime, truths: &[TruthConfig]) {
        self.truths = vec![TruthState::default(); truths.len()];
        for m in &mut self.monitors {
            m.truth = None;
        }
        let names: Vec<String> = rt.monitor_names().map(str::to_string).collect();
        for name in names {
            let types = fault_types(&name);
            let classes = rt.fault_classes(&name).unwrap_or(&[]);
            if types.is_empty() || classes.is_empty() {
                continue;
            }
            let estimates = rt.estimate_names(&name).unwrap_or(&[]);
            let truth = truths
                .iter()
                .position(|t| estimates.contains(&t.estimate.as_str()));
            let i = match self.monitors.iter().position(|m| m.monitor == name) {
                Some(i) => i,
                None => {
                    let truth_names: Vec<&str> = types.iter().map(|t| t.truth).collect();
                    self.monitors.push(MonitorEvaluation {
                        scored_as: types
                            .iter()
                            .map(|t| {
                                t.scored_as
                                    .iter()
                                    .filter_map(|c| classes.iter().position(|k| k == c))
                                    .collect()
                            })
                            .collect(),
                        monitor: name,
                        truth: None,
                        types,
                        evaluator: Evaluator::new(&truth_names),
                    });
                    self.monitors.len() - 1
                }
            };
            let m = &mut self.monitors[i];
            m.truth = truth;
            m.evaluator.start_log();
        }
    }

    /// False alarms and false DTCs counted so far over every monitor.
    pub fn false_counts(&self) -> (u64, u64) {
        self.monitors
            .iter()
            .map(|m| m.evaluator.false_counts())
            .fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
    }

    /// The log ended.
    pub fn end_log(&mut self) {
        for m in &mut self.monitors {
            m.evaluator.end_log();
        }
    }

    /// A truth message of the configuration's truth topic `index`. `observable` is the truth's
    /// `fault_observable` (absent: as `active`).
    pub fn truth(
        &mut self,
        t_ns: u64,
        index: usize,
        fault: &str,
        active: bool,
        observable: Option<bool>,
    ) {
        if let Some(s) = self.truths.get_mut(index) {
            if s.active && !active {
                s.ended_ns = Some(t_ns);
            }
            s.seen = true;
            s.active = active;
            s.observable = active && observable.unwrap_or(true);
            if s.fault != fault {
                s.fault.clear();
                s.fault.push_str(fault);
            }
        }
    }

    /// The diagnosis of `monitor`'s step at `t_ns`.
    pub fn diagnosis(&mut self, t_ns: u64, monitor: &str, flagged: bool, scores: &[f64]) {
        let Some(m) = self.monitors.iter_mut().find(|m| m.monitor == monitor) else {
            return;
        };
        let Some(state) = m.truth.and_then(|i| self.truths.get(i)) else {
            return;
        };
        if !state.seen {
            return;
        }
        let healing = state
            .ended_ns
            .is_some_and(|e| (t_ns.saturating_sub(e) as f64) * 1e-9 < HEAL_GRACE_S);
        let truth = if !state.active && healing {
            Truth::Ignored
        } else if !state.active {
            Truth::FaultFree
        } else {
            // Two faults at once are written `a+b`: the sample counts for the first one the
            // table knows.
            match state
                .fault
                .split('+')
                .find_map(|f| m.types.iter().position(|t| t.truth == f))
            {
                Some(i) if state.observable => Truth::Faulty(i),
                Some(_) => Truth::Ignored,
                None => {
                    *self.unknown_faults.entry(state.fault.clone()).or_insert(0) += 1;
                    Truth::Ignored
                }
            }
        };
        self.scores.clear();
        for classes in &m.scored_as {
            let s: f64 = classes
                .iter()
                .filter_map(|&c| scores.get(c))
                .filter(|v| v.is_finite())
                .sum();
            self.scores.push(s.clamp(0.0, 1.0));
        }
        if let Err(e) = m
            .evaluator
            .sample(t_ns as f64 * 1e-9, truth, flagged, &self.scores)
        {
            self.refused += 1;
            self.first_refusal
                .get_or_insert_with(|| format!("monitor `{monitor}`: {e}"));
        }
    }

    /// A status change of one of `monitor`'s events at `t_ns`; a raised DTC (testFailed 0 -> 1)
    /// is judged against the truth. A group event's DTC ([`group_events`]) is a group DTC whose
    /// candidates are the fault types scored as one of its isolation candidates (those with a
    /// positive score); any other DTC is specific, correct for the fault types that list it.
    /// While two faults act together, a DTC right for either is right.
    pub fn event(&mut self, t_ns: u64, monitor: &str, ev: &EventView<'_>) {
        if !ev.raised() {
            return;
        }
        let Some(m) = self.monitors.iter_mut().find(|m| m.monitor == monitor) else {
            return;
        };
        self.classes.clear();
        let kind = if group_events(monitor).contains(&ev.event) {
            self.classes.extend(
                m.types
                    .iter()
                    .enumerate()
                    .filter(|(_, t)| {
                        ev.candidates
                            .iter()
                            .any(|(c, s)| *s > 0.0 && t.scored_as.contains(c))
                    })
                    .map(|(i, _)| i),
            );
            DtcKind::Group
        } else {
            self.classes.extend(
                m.types
                    .iter()
                    .enumerate()
                    .filter(|(_, t)| t.dtcs.contains(&ev.event))
                    .map(|(i, _)| i),
            );
            DtcKind::Specific
        };
        // Two faults at once (`a+b`): the episode is the first fault's, but a DTC that names
        // the other one present is right too (two DTCs where the faults are isolable; a group
        // DTC naming either): it counts as naming the episode's fault.
        if let Some(state) = m.truth.and_then(|i| self.truths.get(i)) {
            if state.active && state.fault.contains('+') {
                let active: Vec<usize> = state
                    .fault
                    .split('+')
                    .filter_map(|f| m.types.iter().position(|t| t.truth == f))
                    .collect();
                if let Some(&first) = active.first() {
                    if active.iter().any(|a| self.classes.contains(a))
                        && !self.classes.contains(&first)
                    {
                        self.classes.push(first);
                    }
                }
            }
        }
        if let Err(e) = m.evaluator.dtc(t_ns as f64 * 1e-9, &self.classes, kind) {
            self.refused += 1;
            self.first_refusal
                .get_or_insert_with(|| format!("monitor `{monitor}`: {e}"));
        }
    }

    /// Each evaluated monitor's figures, in the order first seen.
    pub fn reports(&mut self) -> Vec<(String, EvaluationReport)> {
        self.monitors
            .iter_mut()
            .map(|m| (m.monitor.clone(), m.evaluator.report()))
            .collect()
    }
}
