//! Where monitor outputs go during a replay: the events file (`--events`, JSON lines), the
//! output MCAP (`--out`, the fdd topics), and the collectors behind the summary (DTCs raised,
//! detection delays, estimate error against ground truth).
//!
//! Without `--out` and `--events` nothing is serialized: a step's outputs only touch the
//! collectors, and those only for events (status changes) and, when the log has ground truth,
//! the configured estimate.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;

use fdd_diagnostics::dtc::{Dtc, DtcStatus, StatusBit};
use fdd_diagnostics::event::EventView;
use fdd_diagnostics::Verdict;
use fdd_monitor::log::{nan_as_null, vec_nan_as_null, LogWriter};
use fdd_monitor::monitor::Output;
use serde::Serialize;

use super::ReplayError;
use crate::stats::RunningStats;
use fdd_monitor::runtime::config::TruthConfig;
use fdd_monitor::runtime::Runtime;

/// `/fdd/throttle/position`, borrowed (no allocation per message).
#[derive(Serialize)]
struct PositionOut<'a> {
    #[serde(serialize_with = "nan_as_null::serialize")]
    angle_deg: f64,
    #[serde(serialize_with = "nan_as_null::serialize")]
    lower_deg: f64,
    #[serde(serialize_with = "nan_as_null::serialize")]
    upper_deg: f64,
    source: &'a str,
}

/// `/fdd/intake/estimate`, borrowed.
#[derive(Serialize)]
struct IntakeEstimateOut<'a> {
    name: &'a str,
    #[serde(serialize_with = "nan_as_null::serialize")]
    value: f64,
    #[serde(serialize_with = "nan_as_null::serialize")]
    lower: f64,
    #[serde(serialize_with = "nan_as_null::serialize")]
    upper: f64,
    source: &'a str,
}

/// `/fdd/throttle/innovation`, borrowed.
#[derive(Serialize)]
struct InnovationOut<'a> {
    filter: &'a str,
    #[serde(serialize_with = "vec_nan_as_null::serialize")]
    residual: &'a [f64],
    #[serde(serialize_with = "vec_nan_as_null::serialize")]
    variance: &'a [f64],
    #[serde(serialize_with = "nan_as_null::serialize")]
    nis: f64,
    dof: usize,
}

/// `/fdd/diagnosis`, borrowed.
#[derive(Serialize)]
struct DiagnosisOut<'a> {
    monitor: &'a str,
    flagged: bool,
    classes: &'a [&'static str],
    scores: &'a [f64],
}

/// `/fdd/tests`, borrowed.
#[derive(Serialize)]
struct TestOut<'a> {
    test: &'a str,
    #[serde(serialize_with = "nan_as_null::serialize")]
    value: f64,
    #[serde(serialize_with = "nan_as_null::serialize")]
    min: f64,
    #[serde(serialize_with = "nan_as_null::serialize")]
    max: f64,
    verdict: Verdict,
}

/// `/fdd/dtc_status`.
#[derive(Serialize)]
struct DtcStatusOut {
    dtc: Dtc,
    status: u8,
}

/// Output topics of `--out`.
pub const POSITION_TOPIC: &str = "/fdd/throttle/position";
pub const INNOVATION_TOPIC: &str = "/fdd/throttle/innovation";
/// The intake monitor's estimates and innovations.
pub const INTAKE_ESTIMATE_TOPIC: &str = "/fdd/intake/estimate";
pub const INTAKE_INNOVATION_TOPIC: &str = "/fdd/intake/innovation";
pub const TESTS_TOPIC: &str = "/fdd/tests";
pub const DTC_STATUS_TOPIC: &str = "/fdd/dtc_status";
pub const EVENTS_TOPIC: &str = "/fdd/events";
/// Each monitor step's diagnosis: the detection flag and the score per fault class.
pub const DIAGNOSIS_TOPIC: &str = "/fdd/diagnosis";

/// One event (DTC) of a monitor, as seen through its status changes.
#[derive(Debug, Clone, PartialEq)]
pub struct DtcRecord {
    /// The configured event name (`wattmeter_no_signal`).
    pub event: String,
    pub dtc: Dtc,
    /// Time testFailed first went 0 -> 1, s.
    pub first_failed_s: Option<f64>,
    /// How many times testFailed went 0 -> 1.
    pub raised: u32,
    /// Status changes seen.
    pub changes: u64,
    /// The latest status byte.
    pub status: DtcStatus,
}

/// A fault of the ground truth, as one truth topic reports it (a log with the throttle and the
/// intake has two, each with its own faults and onsets).
#[derive(Debug, Clone, PartialEq)]
pub struct FaultOnset {
    /// The truth topic (`/truth/throttle`).
    pub topic: String,
    /// Index of the truth topic in the configuration's `[[truth]]`.
    pub truth: usize,
    /// The truth's fault name (`tps_open`).
    pub fault: String,
    /// First log time at which it was active, ns.
    pub onset_ns: u64,
    /// The first DTC raised (testFailed 0 -> 1) at or after the onset by a monitor of this
    /// truth topic (the one whose estimate the topic's `[[truth]]` compares), or by a monitor
    /// of no truth topic (the "no signal" monitor): (DTC, event, time s).
    pub detected: Option<(Dtc, String, f64)>,
    /// Log time during which the truth said the fault was observable (`fault_observable`), from
    /// the onset to the detection (or the end), ns; `None` when the truth does not say.
    pub observable_ns: Option<u64>,
}

/// The comparison of one estimate with its ground truth.
#[derive(Debug, Clone, Default)]
pub struct TruthTrack {
    /// The estimate compared (`truth.estimate`).
    pub estimate: String,
    /// The truth field (`truth.field`).
    pub field: String,
    /// Latest true value (NaN before the first truth message).
    pub value: f64,
    /// Estimates of this name seen.
    pub estimates: u64,
    /// Source of the first estimate (`tps`), and the time the source first changed (a switch to
    /// a fallback estimate), ns.
    pub first_source: Option<String>,
    pub switched_at_ns: Option<u64>,
    /// Error over all estimates with a truth, and after the switch.
    pub error_all: RunningStats,
    pub error_after_switch: RunningStats,
}

/// The collectors and writers. Written to from inside monitor steps, so errors are kept in
/// `error` and checked by the replay loop after each call.
pub struct Sinks<'o> {
    events_file: Option<(PathBuf, BufWriter<File>)>,
    /// `--samples`: every sample the runtime accepted, as CSV.
    pub samples_file: Option<(PathBuf, BufWriter<File>)>,
    out: Option<LogWriter<BufWriter<File>>>,
    /// The first write error; nothing more is written after it.
    pub error: Option<ReplayError>,
    /// Status changes (DiagnosticEvents) seen.
    pub events: u64,
    /// Events written to the events file.
    pub events_written: u64,
    /// One record per event that changed status, in order of first change.
    pub dtcs: Vec<DtcRecord>,
    /// One comparison per `[[truth]]` entry, in configuration order.
    pub truths: Vec<TruthTrack>,
    /// Faults seen active in the truth, in order of onset.
    pub onsets: Vec<FaultOnset>,
    /// Each monitor's truth topic (index into `[[truth]]`: the one whose estimate it outputs);
    /// a monitor not listed has none.
    pub monitor_truth: Vec<(String, usize)>,
    /// Outputs of kinds `--out` has no topic for (estimates of other names).
    pub unwritten: u64,
    /// Each monitor's diagnosis classes (the names of its `scores`), for `--out`.
    pub classes: Vec<(String, &'static [&'static str])>,
    /// A client watching every output (`fdd evaluate`, `fdd calibrate`).
    pub observer: Option<&'o mut dyn ReplayObserver>,
}

/// A client of a replay that sees every monitor output and the ground truth as they happen
/// (`fdd evaluate` and `fdd calibrate` are replays with an observer).
pub trait ReplayObserver {
    /// A log starts, replayed by `rt`; `truths` are the configuration's truth topics.
    fn begin_log(&mut self, rt: &Runtime, truths: &[TruthConfig]);
    /// One output of `monitor`'s step at `t_ns`.
    fn output(&mut self, t_ns: u64, monitor: &str, output: &Output<'_>);
    /// A truth message of truth topic `index` (its `fault`, `fault_active` and, if the truth
    /// says, `fault_observable`).
    fn truth(
        &mut self,
        t_ns: u64,
        index: usize,
        fault: &str,
        active: bool,
        observable: Option<bool>,
    );
    /// A sample of runtime signal `signal` at `t_ns` that the runtime accepted (`fdd
    /// calibrate` gathers the throttle's raw signals to re-identify its model).
    fn sample(&mut self, _t_ns: u64, _signal: &str, _value: f64) {}
    /// The log ended.
    fn end_log(&mut self);
}

impl Sinks<'_> {
    pub fn new(
        events_file: Option<(PathBuf, BufWriter<File>)>,
        out: Option<LogWriter<BufWriter<File>>>,
        truths: &[crate::replay::config::TruthConfig],
    ) -> Self {
        Sinks {
            events_file,
            samples_file: None,
            out,
            error: None,
            events: 0,
            events_written: 0,
            dtcs: Vec::new(),
            truths: truths
                .iter()
                .map(|t| TruthTrack {
                    estimate: t.estimate.clone(),
                    field: t.field.clone(),
                    value: f64::NAN,
                    ..TruthTrack::default()
                })
                .collect(),
            onsets: Vec::new(),
            monitor_truth: Vec::new(),
            unwritten: 0,
            classes: Vec::new(),
            observer: None,
        }
    }

    /// Takes one output of `monitor`'s step at `t_ns`.
    pub fn on_output(&mut self, t_ns: u64, monitor: &str, o: Output<'_>) {
        if let Some(obs) = self.observer.as_mut() {
            obs.output(t_ns, monitor, &o);
        }
        match o {
            Output::Event(ev) => self.on_event(t_ns, monitor, ev),
            Output::Diagnosis { flagged, scores } => {
                if self.out.is_some() {
                    let classes = self
                        .classes
                        .iter()
                        .find(|(m, _)| m == monitor)
                        .map_or(&[][..], |(_, c)| *c);
                    self.write_out(DIAGNOSIS_TOPIC, t_ns, || DiagnosisOut {
                        monitor,
                        flagged,
                        classes,
                        scores,
                    });
                }
            }
            Output::Estimate {
                name,
                value,
                lower,
                upper,
                source,
            } => {
                if let Some(tr) = self.truths.iter_mut().find(|t| t.estimate == name) {
                    tr.estimates += 1;
                    match &tr.first_source {
                        None => tr.first_source = Some(source.to_string()),
                        Some(first) if tr.switched_at_ns.is_none() && first != source => {
                            tr.switched_at_ns = Some(t_ns);
                        }
                        Some(_) => {}
                    }
                    let err = value - tr.value;
                    if err.is_finite() {
                        tr.error_all.push(err);
                        if tr.switched_at_ns.is_some() {
                            tr.error_after_switch.push(err);
                        }
                    }
                }
                if name == "throttle_angle" {
                    self.write_out(POSITION_TOPIC, t_ns, || PositionOut {
                        angle_deg: value,
                        lower_deg: lower,
                        upper_deg: upper,
                        source,
                    });
                } else if name == "manifold_pressure" || name == "intake_valve_flow" {
                    self.write_out(INTAKE_ESTIMATE_TOPIC, t_ns, || IntakeEstimateOut {
                        name,
                        value,
                        lower,
                        upper,
                        source,
                    });
                } else if self.out.is_some() {
                    self.unwritten += 1;
                }
            }
            Output::Innovation {
                filter,
                residual,
                variance,
                nis,
                dof,
            } => self.write_out(
                if filter.starts_with("intake_") {
                    INTAKE_INNOVATION_TOPIC
                } else {
                    INNOVATION_TOPIC
                },
                t_ns,
                || InnovationOut {
                    filter,
                    residual,
                    variance,
                    nis,
                    dof,
                },
            ),
            Output::Test { test, result } => self.write_out(TESTS_TOPIC, t_ns, || TestOut {
                test,
                value: result.value,
                min: result.min,
                max: result.max,
                verdict: result.verdict,
            }),
            Output::DtcStatus { dtc, status } => {
                self.write_out(DTC_STATUS_TOPIC, t_ns, || DtcStatusOut {
                    dtc,
                    status: status.byte(),
                })
            }
        }
    }

    fn write_out<T: Serialize>(&mut self, topic: &str, t_ns: u64, msg: impl FnOnce() -> T) {
        if self.error.is_some() {
            return;
        }
        if let Some(w) = self.out.as_mut() {
            if let Err(e) = w.write(topic, t_ns, &msg()) {
                self.error = Some(ReplayError::Log(e));
            }
        }
    }

    fn on_event(&mut self, t_ns: u64, monitor: &str, ev: &EventView<'_>) {
        self.events += 1;
        let raised = ev.bit_changed(StatusBit::TestFailed) && ev.status_after.test_failed();
        let k = match self.dtcs.iter().position(|d| d.event == ev.event) {
            Some(k) => k,
            None => {
                self.dtcs.push(DtcRecord {
                    event: ev.event.to_string(),
                    dtc: ev.dtc,
                    first_failed_s: None,
                    raised: 0,
                    changes: 0,
                    status: ev.status_after,
                });
                self.dtcs.len() - 1
            }
        };
        let d = &mut self.dtcs[k];
        d.changes += 1;
        d.status = ev.status_after;
        if raised {
            d.raised += 1;
            d.first_failed_s.get_or_insert(ev.time_s);
            tracing::info!(
                dtc = %ev.dtc,
                event = %ev.event,
                "DTC {} raised (testFailed) at {:.6} s: {}",
                ev.dtc,
                ev.time_s,
                ev.event
            );
            let onset_limit = ev.time_s;
            let truth = self
                .monitor_truth
                .iter()
                .find(|(m, _)| m == monitor)
                .map(|(_, t)| *t);
            for f in &mut self.onsets {
                let ours = truth.is_none_or(|t| t == f.truth);
                if ours && f.detected.is_none() && f.onset_ns as f64 * 1e-9 <= onset_limit {
                    f.detected = Some((ev.dtc, ev.event.to_string(), ev.time_s));
                }
            }
        } else {
            tracing::debug!(
                dtc = %ev.dtc,
                event = %ev.event,
                "status {:#04x} -> {:#04x} at {:.6} s",
                ev.status_before.byte(),
                ev.status_after.byte(),
                ev.time_s
            );
        }
        if self.error.is_some() {
            return;
        }
        if let Some((path, w)) = self.events_file.as_mut() {
            let res = serde_json::to_writer(&mut *w, ev)
                .map_err(std::io::Error::from)
                .and_then(|()| w.write_all(b"\n"));
            match res {
                Ok(()) => self.events_written += 1,
                Err(source) => {
                    self.error = Some(ReplayError::Events {
                        file: path.clone(),
                        source,
                    })
                }
            }
        }
        self.write_out(EVENTS_TOPIC, t_ns, || ev);
    }

    /// Truth topic `truth` says whether its active faults are observable over the `dt_ns` that
    /// ends with this sample: adds it to every fault of that topic not yet detected.
    pub fn fault_observable(&mut self, truth: usize, observable: bool, dt_ns: u64) {
        for f in self
            .onsets
            .iter_mut()
            .filter(|f| f.truth == truth && f.detected.is_none())
        {
            let acc = f.observable_ns.get_or_insert(0);
            if observable {
                *acc += dt_ns;
            }
        }
    }

    /// A fault of truth topic `truth` (`topic`) became active at `t_ns` (first time for this
    /// name on this topic).
    pub fn fault_onset(&mut self, truth: usize, topic: &str, fault: &str, t_ns: u64) {
        if self
            .onsets
            .iter()
            .any(|f| f.truth == truth && f.fault == fault)
        {
            return;
        }
        tracing::info!(
            fault,
            "ground truth ({topic}): fault '{fault}' active from {:.6} s",
            t_ns as f64 * 1e-9
        );
        self.onsets.push(FaultOnset {
            topic: topic.to_string(),
            truth,
            fault: fault.to_string(),
            onset_ns: t_ns,
            detected: None,
            observable_ns: None,
        });
    }

    /// Writes one row `t_ns,signal,value` of the samples file (`--samples`): the value in
    /// Rust's shortest round-trip form, so a reader parsing it gets the same `f64`.
    pub fn sample(&mut self, t_ns: u64, signal: &str, value: f64) {
        if self.error.is_some() {
            return;
        }
        if let Some((path, w)) = self.samples_file.as_mut() {
            if let Err(source) = writeln!(w, "{t_ns},{signal},{value:?}") {
                self.error = Some(ReplayError::Samples {
                    file: path.clone(),
                    source,
                });
            }
        }
    }

    /// Flushes the events file and finishes the output MCAP. Returns (events file, events
    /// written) and (out file, messages written).
    #[allow(clippy::type_complexity)]
    pub fn finish(
        &mut self,
    ) -> Result<(Option<(PathBuf, u64)>, Option<(PathBuf, u64)>), ReplayError> {
        let mut events = None;
        if let Some((path, mut w)) = self.events_file.take() {
            w.flush().map_err(|source| ReplayError::Events {
                file: path.clone(),
                source,
            })?;
            events = Some((path, self.events_written));
        }
        if let Some((path, mut w)) = self.samples_file.take() {
            w.flush()
                .map_err(|source| ReplayError::Samples { file: path, source })?;
        }
        let mut out = None;
        if let Some(w) = self.out.take() {
            let path = w.file().to_path_buf();
            let n = w.messages_written();
            w.finish()?;
            out = Some((path, n));
        }
        Ok((events, out))
    }
}
