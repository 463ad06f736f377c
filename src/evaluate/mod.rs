//! `fdd evaluate`: replays logs that carry ground truth and scores the monitors the way the
//! diagnosis community does (the DX'25 diagnostic competition's TDR, FAR and FIA, see
//! [`fdd_diagnostics::evaluation`]), plus per fault type the detection rate, the DTC rates and
//! the delays, and false alarms per hour of fault-free time.
//!
//! - **Inputs**: MCAP logs, scenario files (`.toml`, simulated into a temporary MCAP first, so
//!   a scenario set needs no stored logs), and directories of either (their `.mcap` and `.toml`
//!   files, in name order).
//! - **Samples** are the monitors' steps: each step's [`fdd_monitor::monitor::Output::Diagnosis`]
//!   is judged against the ground truth of the latest truth message before it (fault-free,
//!   faulty with its fault type, or not counted while a fault is active without an observable
//!   effect). Which faults count as which classes and DTCs: [`fault_types`].
//! - **Logs** are replayed exactly as by `fdd replay` (same configuration, same runtime); each
//!   is its own operation cycle.

pub mod collector;
pub mod fault_types;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use fdd_diagnostics::evaluation::EvaluationReport;
use serde::Serialize;

pub use collector::Evaluation;

use crate::replay::{replay_observed, ReplayError, ReplayOptions, RuntimeConfig};
use crate::simulate::SimulateError;

/// Why an evaluation could not run.
#[derive(Debug, thiserror::Error)]
pub enum EvaluateError {
    #[error("{}: cannot list the directory: {source}", dir.display())]
    Dir {
        dir: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: neither an MCAP log (.mcap), a scenario (.toml) nor a directory", .0.display())]
    NotALog(PathBuf),
    #[error("no logs to evaluate (the directories given hold no .mcap or .toml file)")]
    NoLogs,
    #[error("cannot create a temporary file for the simulated log: {0}")]
    Temp(#[source] std::io::Error),
    #[error("{}: {source}", file.display())]
    Simulate {
        file: PathBuf,
        #[source]
        source: Box<SimulateError>,
    },
    #[error(transparent)]
    Replay(#[from] ReplayError),
    #[error("{}: the replay stopped early: {message}", file.display())]
    StoppedEarly { file: PathBuf, message: String },
}

/// One evaluated log.
#[derive(Debug, Clone, Serialize)]
pub struct LogResult {
    /// The log or scenario file.
    pub file: PathBuf,
    /// Frames replayed.
    pub frames: u64,
    /// Log time covered (s).
    pub duration_s: f64,
    /// DTCs raised (testFailed 0 -> 1), as `DTC event @ time_s`.
    pub dtcs: Vec<String>,
    /// Per estimate whose source changed in this log (the throttle position switched from the
    /// TPS to the wattmeter estimate), its error against the truth from the switch on.
    pub after_switch: Vec<SwitchError>,
    /// False alarms and false DTCs in this log, over every monitor (where the set totals come
    /// from).
    pub false_alarms: u64,
    pub false_dtcs: u64,
}

/// An estimate's error against the truth after its source first changed in a log.
#[derive(Debug, Clone, Serialize)]
pub struct SwitchError {
    /// The estimate (`throttle_angle`).
    pub estimate: String,
    /// Log time of the switch (s).
    pub switched_at_s: f64,
    /// Estimates compared after the switch, their mean error and standard deviation (the
    /// estimate's unit: deg for the throttle position).
    pub samples: u64,
    pub mean: f64,
    pub std: f64,
}

/// Everything `fdd evaluate` prints.
#[derive(Debug, Clone, Serialize)]
pub struct EvaluateSummary {
    pub config: String,
    pub logs: Vec<LogResult>,
    /// Per monitor with ground truth, its figures over every log.
    pub monitors: Vec<MonitorFigures>,
    /// Truth fault names not in the fault-type table, with the samples left uncounted.
    pub unknown_faults: Vec<(String, u64)>,
}

/// One monitor's figures.
#[derive(Debug, Clone, Serialize)]
pub struct MonitorFigures {
    pub monitor: String,
    #[serde(flatten)]
    pub report: EvaluationReport,
}

/// The logs named by `inputs`: files as given, directories expanded to their `.mcap` and
/// `.toml` files in name order.
pub fn expand_inputs(inputs: &[PathBuf]) -> Result<Vec<PathBuf>, EvaluateError> {
    let mut logs = Vec::new();
    for p in inputs {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|source| EvaluateError::Dir {
                    dir: p.clone(),
                    source,
                })?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.is_file() && matches!(extension(f), Some("mcap" | "toml")))
                .collect();
            found.sort();
            logs.extend(found);
        } else if matches!(extension(p), Some("mcap" | "toml")) {
            logs.push(p.clone());
        } else {
            return Err(EvaluateError::NotALog(p.clone()));
        }
    }
    if logs.is_empty() {
        return Err(EvaluateError::NoLogs);
    }
    Ok(logs)
}

fn extension(p: &Path) -> Option<&str> {
    p.extension().and_then(|e| e.to_str())
}

/// Evaluates the monitors of `cfg` on `inputs` (see the [module documentation](self)).
/// `progress` is called with each log before it runs.
pub fn evaluate(
    inputs: &[PathBuf],
    cfg: &RuntimeConfig,
    sim: &crate::simulate::SimulateOptions,
    mut progress: impl FnMut(usize, usize, &Path),
) -> Result<EvaluateSummary, EvaluateError> {
    let logs = expand_inputs(inputs)?;
    let mut evaluation = Evaluation::default();
    let mut results = Vec::with_capacity(logs.len());
    let opts = ReplayOptions::default();
    for (i, file) in logs.iter().enumerate() {
        progress(i, logs.len(), file);
        let before = evaluation.false_counts();
        let summary = if extension(file) == Some("toml") {
            let tmp = tempfile::Builder::new()
                .prefix("fdd-evaluate-")
                .suffix(".mcap")
                .tempfile()
                .map_err(EvaluateError::Temp)?;
            let arg = file.to_string_lossy();
            crate::simulate::simulate(&arg, tmp.path(), sim).map_err(|source| {
                EvaluateError::Simulate {
                    file: file.clone(),
                    source: Box::new(source),
                }
            })?;
            replay_observed(tmp.path(), cfg, &opts, &mut evaluation)?
        } else {
            replay_observed(file, cfg, &opts, &mut evaluation)?
        };
        let after = evaluation.false_counts();
        if let Some(message) = summary.stopped_early {
            return Err(EvaluateError::StoppedEarly {
                file: file.clone(),
                message,
            });
        }
        results.push(LogResult {
            file: file.clone(),
            frames: summary.frames,
            duration_s: summary
                .time_range_ns
                .map_or(0.0, |(a, b)| (b - a) as f64 * 1e-9),
            dtcs: summary
                .dtcs
                .iter()
                .filter_map(|d| {
                    d.first_failed_s
                        .map(|t| format!("{} {} @ {t:.3}", d.dtc, d.event))
                })
                .collect(),
            after_switch: summary
                .truth
                .iter()
                .flat_map(|t| &t.estimates)
                .filter_map(|e| {
                    let (at, err) = (e.switched_at_ns?, e.error_after_switch?);
                    (err.samples > 0).then(|| SwitchError {
                        estimate: e.estimate.clone(),
                        switched_at_s: at as f64 * 1e-9,
                        samples: err.samples,
                        mean: err.mean,
                        std: err.std,
                    })
                })
                .collect(),
            false_alarms: after.0 - before.0,
            false_dtcs: after.1 - before.1,
        });
    }
    if let Some(msg) = &evaluation.first_refusal {
        tracing::warn!(
            "{} samples or DTCs were not counted; the first: {msg}",
            evaluation.refused
        );
    }
    Ok(EvaluateSummary {
        config: cfg.origin.clone(),
        logs: results,
        monitors: evaluation
            .reports()
            .into_iter()
            .map(|(monitor, report)| MonitorFigures { monitor, report })
            .collect(),
        unknown_faults: evaluation.unknown_faults.into_iter().collect(),
    })
}

fn pct(x: f64) -> String {
    if x.is_nan() {
        "-".into()
    } else {
        format!("{:.1} %", 100.0 * x)
    }
}

fn secs(x: f64) -> String {
    if x.is_nan() {
        "-".into()
    } else {
        format!("{x:.2}")
    }
}

impl EvaluateSummary {
    /// The tables `fdd evaluate` prints.
    pub fn render(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "config: {}", self.config);
        let _ = writeln!(s, "logs: {}", self.logs.len());
        for m in &self.monitors {
            let r = &m.report;
            let _ = writeln!(
                s,
                "\n{}: {} logs, {:.2} h fault-free, {} faulty and {} fault-free samples",
                m.monitor, r.logs, r.fault_free_hours, r.faulty_samples, r.fault_free_samples
            );
            let _ = writeln!(
                s,
                "  TDR {}   FAR {}   FIA {}   false alarms {} ({}/h)   false DTCs {} ({}/h)",
                pct(r.tdr),
                pct(r.far),
                pct(r.fia),
                r.false_alarms,
                rate(r.false_alarms_per_hour),
                r.false_dtcs,
                rate(r.false_dtcs_per_hour)
            );
            let _ = writeln!(
                s,
                "  {:<18} {:>4} {:>9} {:>9} {:>9} {:>6} {:>6} {:>13} {:>13} {:>13}",
                "fault",
                "eps",
                "detected",
                "any DTC",
                "correct",
                "wrong",
                "group",
                "detect med/max",
                "DTC med/max",
                "correct med/max"
            );
            for c in r.classes.iter().filter(|c| c.episodes > 0) {
                let _ = writeln!(
                    s,
                    "  {:<18} {:>4} {:>9} {:>9} {:>9} {:>6} {:>6} {:>13} {:>13} {:>13}",
                    c.class,
                    c.episodes,
                    pct(c.detection_rate),
                    pct(c.dtc_rate),
                    pct(c.correct_dtc_rate),
                    c.wrong_dtc,
                    if c.group_missed > 0 {
                        format!("{}/{}!", c.group_dtc, c.group_missed)
                    } else {
                        c.group_dtc.to_string()
                    },
                    format!(
                        "{}/{}",
                        secs(c.median_detection_delay_s),
                        secs(c.worst_detection_delay_s)
                    ),
                    format!(
                        "{}/{}",
                        secs(c.median_any_dtc_delay_s),
                        secs(c.worst_any_dtc_delay_s)
                    ),
                    format!(
                        "{}/{}",
                        secs(c.median_dtc_delay_s),
                        secs(c.worst_dtc_delay_s)
                    ),
                );
            }
        }
        self.render_switches(&mut s);
        if self.monitors.is_empty() {
            let _ = writeln!(
                s,
                "\nno monitor had ground truth to be judged against (no /truth topics?)"
            );
        }
        for (fault, samples) in &self.unknown_faults {
            let _ = writeln!(
                s,
                "note: truth fault `{fault}` is not a known fault type: {samples} samples not counted"
            );
        }
        let _ = writeln!(
            s,
            "\nTDR: share of faulty samples flagged; FAR: share of fault-free samples flagged; FIA: mean score of the true fault over the flagged faulty samples (DX'25). Delays in s from the fault's first observable sample; `group` counts episodes with a group DTC (`n/m!`: m of them lacked the true fault)."
        );
        s
    }
}

impl EvaluateSummary {
    /// Per estimate that switched source in some log: in how many logs, and the median and
    /// worst standard deviation of its error after the switch (the throttle issue's bound on
    /// the position error after the switch to the wattmeter estimate is about the worst).
    fn render_switches(&self, s: &mut String) {
        let mut names: Vec<&str> = self
            .logs
            .iter()
            .flat_map(|l| l.after_switch.iter().map(|e| e.estimate.as_str()))
            .collect();
        names.sort_unstable();
        names.dedup();
        for name in names {
            let mut stds: Vec<(f64, &Path)> = self
                .logs
                .iter()
                .flat_map(|l| {
                    l.after_switch
                        .iter()
                        .filter(|e| e.estimate == name)
                        .map(|e| (e.std, l.file.as_path()))
                })
                .collect();
            stds.sort_by(|a, b| a.0.total_cmp(&b.0));
            let median = stds[stds.len() / 2].0;
            let (worst, file) = stds[stds.len() - 1];
            let _ = writeln!(
                s,
                "\n{name} after its source switched: {} logs, error std median {median:.2}, worst {worst:.2} ({})",
                stds.len(),
                file.file_name().map_or_else(|| file.display().to_string(), |f| f.to_string_lossy().into_owned())
            );
        }
    }
}

fn rate(x: f64) -> String {
    if x.is_nan() {
        "-".into()
    } else {
        format!("{x:.3}")
    }
}
