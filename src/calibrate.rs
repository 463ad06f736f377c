//! `fdd calibrate`: from fault-free logs of one plant, what the throttle monitor assumes: its
//! sensors' noise levels and every residual test's threshold for a stated false-alarm rate,
//! written as a configuration that `fdd replay --config` uses.
//!
//! Method (a client of the runtime, like `replay`):
//!
//! 1. Every log is replayed with the monitor's thresholds out of reach (nothing fails, nothing
//!    is decided, so every step is a fault-free sample of every test statistic) and wide noise
//!    bounds. The monitor's online noise estimates (`tps_noise_std_v`,
//!    `wattmeter_noise_std_w`, see `fdd_estimators::NoiseLevel`) at the end of each log give
//!    the noise levels (the median over the logs).
//! 2. **The model** (unless `--keep-model`): the same pass gathers the motor voltage, TPS and
//!    wattmeter samples, and the throttle model (27 Table I values) is re-identified from
//!    them by prediction error ([`fdd_estimators::models::throttle_identification`]) at those
//!    noise levels. A plant a few percent off Table I is fitted a little better; one 20 % off
//!    (the wattmeter residual of the default fails within seconds) becomes testable at all.
//!    The wattmeter residual's model error (the dead band `watt_model_error_w`) is then
//!    measured again with the identified model.
//! 3. A second pass runs with those noise levels (and model). Each test's statistic is cut into blocks of
//!    `block_s` seconds; a generalized extreme-value law is fitted to the block maxima by
//!    L-moments ([`fdd_diagnostics::extreme_value::GevFit`]: a CUSUM fed by model error that
//!    comes and goes has a heavier tail than Gumbel's) and the threshold is the value a block maximum
//!    exceeds with probability `rate * block_s / 3600`: it extrapolates beyond the largest
//!    value seen.
//! 4. **Refusals.** A log whose ground truth says a fault is active; fewer than 20 blocks of a
//!    statistic; a rate asking to extrapolate more than [`MAX_EXTRAPOLATION`] times the data's
//!    length; block maxima that do not follow the law (probability-plot correlation below
//!    [`MIN_PPCC`]), or one above the threshold it gives (the data would alarm at the rate
//!    asked): each says which test, log and time.

use std::path::{Path, PathBuf};

use fdd_diagnostics::extreme_value::{FitError, GevFit};
use fdd_diagnostics::Verdict;
use fdd_estimators::models::throttle_identification::{
    identify, IdSample, Identified, IdentifyError, IdentifySettings, IDENTIFIED_KEYS,
};
use fdd_monitor::monitor::Output;
use fdd_monitor::runtime::config::TruthConfig;
use fdd_monitor::runtime::Runtime;

pub mod intake;
pub mod turbo;

use crate::evaluate::expand_inputs;
use crate::replay::{replay_observed, ReplayObserver, ReplayOptions, RuntimeConfig};

/// Smallest probability-plot correlation of a fit that is accepted.
pub const MIN_PPCC: f64 = 0.95;
/// Largest ratio of the return period asked (`1 / rate`) to the data's length.
pub const MAX_EXTRAPOLATION: f64 = 1e4;
/// Thresholds of the calibration runs: out of reach of any fault-free statistic, finite (the
/// CUSUMs' run-length solution needs it).
const UNREACHABLE_CUSUM: f64 = 400.0;
const UNREACHABLE_NIS: f64 = 1e12;

/// The runtime signals the model is re-identified from: motor voltage, TPS, wattmeter.
const IDENTIFICATION_SIGNALS: [&str; 3] = ["motor_voltage", "tps", "wattmeter"];
/// Samples per log kept for the identification (1 h at 1 kHz, 86 MB): bounds the memory on
/// long logs; a longer log identifies from its first hour.
const MAX_IDENTIFICATION_SAMPLES: usize = 3_600_000;

/// Time constant of the low-pass that separates the wattmeter residual's slowly varying part
/// (model error) from its noise (s).
const MODEL_ERROR_TAU_S: f64 = 0.1;

/// The throttle tests calibrated: (test output name, `[monitor]` key).
const TESTS: [(&str, &str); 4] = [
    ("tps_nis_window", "tps_nis_threshold"),
    ("tps_cusum", "tps_cusum_threshold"),
    ("wattmeter_cusum", "watt_cusum_threshold"),
    ("tps_step", "tps_step_sigma"),
];

/// Why a calibration was refused or could not run.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    #[error(transparent)]
    Evaluate(#[from] crate::evaluate::EvaluateError),
    #[error(transparent)]
    Replay(#[from] crate::replay::ReplayError),
    #[error(transparent)]
    Config(#[from] fdd_monitor::config::ConfigError),
    #[error("{}: not fault-free: the ground truth has `{fault}` active at {t_s:.3} s", file.display())]
    FaultInLog {
        file: PathBuf,
        fault: String,
        t_s: f64,
    },
    #[error("no data for `{0}` in the logs (its monitor produced none: are they logs of that monitor's subsystem?)")]
    NoData(&'static str),
    #[error("test `{test}`: {source} ({hours:.2} h of data in blocks of {block_s} s); give longer or more logs")]
    TooShort {
        test: &'static str,
        hours: f64,
        block_s: f64,
        #[source]
        source: FitError,
    },
    #[error("{rate} false alarms per hour asks to extrapolate {ratio:.0} times beyond {hours:.2} h of data (at most {MAX_EXTRAPOLATION:.0}); give longer logs or a higher rate")]
    Extrapolation { rate: f64, hours: f64, ratio: f64 },
    #[error("test `{test}`: the block maxima do not follow an extreme-value law (probability-plot correlation {ppcc:.3} < {MIN_PPCC}); the largest, {max:.4} in {} at {t_s:.1} s, suggests a fault or a change of plant in the data", file.display())]
    BadFit {
        test: &'static str,
        ppcc: f64,
        max: f64,
        file: PathBuf,
        t_s: f64,
    },
    #[error("test `{test}`: the data exceed the threshold they give ({max:.4} > {threshold:.4} in {} at {t_s:.1} s): not fault-free enough for {rate} false alarms per hour", file.display())]
    Exceeds {
        test: &'static str,
        max: f64,
        threshold: f64,
        file: PathBuf,
        t_s: f64,
        rate: f64,
    },
    #[error("{}: cannot read: {source}", file.display())]
    Read {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{}: cannot write: {source}", file.display())]
    Write {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{origin}: {message}")]
    Toml { origin: String, message: String },
    #[error("{}: {message}", file.display())]
    Monitor { file: PathBuf, message: String },
    #[error("{0}")]
    Argument(String),
    /// A text file (a configuration, a scenario) that cannot be read; the message names it.
    #[error(transparent)]
    Text(#[from] fdd_monitor::text_file::TextFileError),
    #[error("{}: refusing to write the calibration over {what}; choose another output directory", file.display())]
    OutputIsInput { file: PathBuf, what: String },
    #[error("monitor `{0}`: fdd calibrate knows `throttle`, `intake` and `turbo`")]
    UnknownMonitor(String),
    #[error("re-identifying the throttle model: {0}")]
    Identify(#[from] IdentifyError),
    #[error("re-identifying the throttle model: {incomplete} of the logs' timestamps lack one of the signals {IDENTIFICATION_SIGNALS:?} (the identification needs the three sampled together)")]
    Unaligned { incomplete: u64 },
}

/// What `fdd calibrate` asks for.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrateOptions {
    /// False alarms per hour of each test (default 1e-3).
    pub false_alarms_per_hour: f64,
    /// Block length of the block maxima (s).
    pub block_s: f64,
    /// Re-identify the throttle model from the logs before the thresholds (default); `false`
    /// keeps the starting configuration's model.
    pub identify: bool,
    /// Simulate scenario files longer than [`crate::simulate::MAX_SIMULATE_S`]
    /// (`--allow-long`).
    pub allow_long: bool,
}

impl Default for CalibrateOptions {
    fn default() -> Self {
        Self {
            false_alarms_per_hour: 1e-3,
            block_s: 10.0,
            identify: true,
            allow_long: false,
        }
    }
}

impl CalibrateOptions {
    /// Checks the rate and the block length against their ranges
    /// ([`crate::limits::CALIBRATE_RATE`], [`crate::limits::CALIBRATE_BLOCK`]).
    pub fn check(&self) -> Result<(), CalibrateError> {
        crate::limits::CALIBRATE_RATE
            .check(self.false_alarms_per_hour)
            .map_err(CalibrateError::Argument)?;
        crate::limits::CALIBRATE_BLOCK
            .check(self.block_s)
            .map_err(CalibrateError::Argument)?;
        Ok(())
    }
}

/// The files `fdd calibrate -o DIR` writes into `DIR`.
pub const WRITTEN_FILES: [&str; 4] = ["fdd.toml", "throttle.toml", "intake.toml", "turbo.toml"];

/// Refuses an output directory where the calibration would write over one of its inputs: the
/// starting configuration (`--config`), a monitor settings file it names, or an input log or
/// scenario file (files compared as files, [`crate::paths::same_file`]). Checked before the
/// calibration runs, so nothing is lost and no time is spent.
pub fn check_output_dir(
    out: &Path,
    inputs: &[PathBuf],
    base: &RuntimeConfig,
) -> Result<(), CalibrateError> {
    let mut read: Vec<(PathBuf, &str)> = Vec::new();
    if Path::new(&base.origin).is_file() {
        read.push((PathBuf::from(&base.origin), "the --config file"));
    }
    for p in [
        &base.monitors.throttle_config,
        &base.monitors.intake_config,
        &base.monitors.turbo_config,
    ]
    .into_iter()
    .flatten()
    {
        read.push((p.clone(), "a monitor settings file the configuration names"));
    }
    for p in expand_inputs(inputs)? {
        read.push((p, "an input"));
    }
    for name in WRITTEN_FILES {
        let written = out.join(name);
        if let Some((_, what)) = read
            .iter()
            .find(|(p, _)| crate::paths::same_file(p, &written))
        {
            return Err(CalibrateError::OutputIsInput {
                file: written,
                what: (*what).to_string(),
            });
        }
    }
    Ok(())
}

/// One test's calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct TestCalibration {
    pub test: &'static str,
    pub key: &'static str,
    pub fit: GevFit,
    /// Largest value seen, and the threshold set.
    pub max: f64,
    pub threshold: f64,
}

/// The result: the levels and thresholds, and the configuration text to write.
#[derive(Debug, Clone)]
pub struct Calibration {
    pub logs: Vec<PathBuf>,
    pub hours: f64,
    pub tps_noise_v: f64,
    pub wattmeter_noise_w: f64,
    /// The wattmeter test's model-error dead band (W).
    pub watt_model_error_w: f64,
    pub tests: Vec<TestCalibration>,
    /// `throttle.toml` and `fdd.toml` texts.
    pub throttle_toml: String,
    pub runtime_toml: String,
    /// The re-identified model, when asked for.
    pub identified: Option<Identified>,
}

/// Statistics of one replay pass.
#[derive(Default)]
struct Collector {
    file: PathBuf,
    block_ns: u64,
    /// Per test: block maxima with their log and start time.
    maxima: [Vec<(f64, usize, f64)>; TESTS.len()],
    current: [Option<(u64, f64)>; TESTS.len()],
    log_index: usize,
    noise: (f64, f64),
    /// Low-passed wattmeter innovation (W, time constant [`MODEL_ERROR_TAU_S`]), the block's
    /// largest magnitude of it, and those block maxima: the model error's size.
    watt_lp: f64,
    watt_lp_block: Option<(u64, f64)>,
    watt_lp_maxima: Vec<f64>,
    fault: Option<(String, f64)>,
    /// With `Some`, the throttle's raw signals per log (for the model's re-identification):
    /// the samples of one timestamp gathered in `pending`, the complete ones kept.
    records: Option<Vec<Vec<IdSample>>>,
    pending: (u64, [Option<f64>; 3]),
    /// Timestamps at which not all three signals arrived (left out of the identification).
    incomplete: u64,
    first_ns: Option<u64>,
    last_ns: u64,
    total_ns: u64,
}

impl Collector {
    /// Keeps the pending timestamp's samples if all three signals arrived.
    fn take_pending(&mut self) {
        let (_, v) = std::mem::take(&mut self.pending);
        let Some(records) = self.records.as_mut() else {
            return;
        };
        match v {
            [Some(u_v), Some(tps_v), Some(watt_w)] => {
                if let Some(r) = records.last_mut() {
                    if r.len() < MAX_IDENTIFICATION_SAMPLES {
                        r.push(IdSample { u_v, tps_v, watt_w });
                    }
                }
            }
            [None, None, None] => {}
            _ => self.incomplete += 1,
        }
    }

    fn flush(&mut self) {
        for (i, c) in self.current.iter_mut().enumerate() {
            if let Some((start, m)) = c.take() {
                self.maxima[i].push((m, self.log_index, start as f64 * 1e-9));
            }
        }
    }
}

impl ReplayObserver for Collector {
    fn begin_log(&mut self, _rt: &Runtime, _truths: &[TruthConfig]) {
        self.current = [None; TESTS.len()];
        self.watt_lp = 0.0;
        self.watt_lp_block = None;
        self.noise = (f64::NAN, f64::NAN);
        self.first_ns = None;
        if let Some(r) = self.records.as_mut() {
            r.push(Vec::new());
        }
        self.pending = (0, [None; 3]);
    }

    fn sample(&mut self, t_ns: u64, signal: &str, value: f64) {
        let Some(k) = IDENTIFICATION_SIGNALS.iter().position(|s| *s == signal) else {
            return;
        };
        if self.records.is_none() {
            return;
        }
        if t_ns != self.pending.0 {
            self.take_pending();
            self.pending.0 = t_ns;
        }
        self.pending.1[k] = Some(value);
    }

    fn output(&mut self, t_ns: u64, monitor: &str, output: &Output<'_>) {
        if monitor != "throttle" {
            return;
        }
        self.first_ns.get_or_insert(t_ns);
        self.last_ns = self.last_ns.max(t_ns);
        match *output {
            Output::Test { test, result } if result.verdict != Verdict::NotTested => {
                let Some(i) = TESTS.iter().position(|(t, _)| *t == test) else {
                    return;
                };
                block_max(
                    &mut self.current[i],
                    &mut self.maxima[i],
                    (t_ns, self.block_ns, self.log_index),
                    result.value,
                );
            }
            Output::Innovation {
                filter: "combined",
                residual,
                ..
            } if residual.len() == 2 && residual[1].is_finite() && residual[1] != 0.0 => {
                let alpha = 1e-3 / MODEL_ERROR_TAU_S;
                self.watt_lp += alpha * (residual[1] - self.watt_lp);
                let v = self.watt_lp.abs();
                match &mut self.watt_lp_block {
                    Some((start, m)) if t_ns < *start + self.block_ns => *m = m.max(v),
                    slot => {
                        if let Some((_, m)) = slot.take() {
                            self.watt_lp_maxima.push(m);
                        }
                        *slot = Some((t_ns, v));
                    }
                }
            }
            Output::Estimate { name, value, .. } => match name {
                "tps_noise_std_v" => self.noise.0 = value,
                "wattmeter_noise_std_w" => self.noise.1 = value,
                _ => {}
            },
            _ => {}
        }
    }

    fn truth(&mut self, t_ns: u64, _index: usize, fault: &str, active: bool, _o: Option<bool>) {
        if active && self.fault.is_none() {
            self.fault = Some((fault.to_string(), t_ns as f64 * 1e-9));
        }
    }

    fn end_log(&mut self) {
        self.take_pending();
        // The last, partial block is dropped.
        self.current = [None; TESTS.len()];
        if let Some(a) = self.first_ns {
            self.total_ns += self.last_ns.saturating_sub(a);
        }
        self.last_ns = 0;
    }
}

/// A TOML text as an editable document (comments kept), errors naming `origin`.
pub(crate) fn parse_doc(
    text: &str,
    origin: &str,
) -> Result<toml_edit::DocumentMut, CalibrateError> {
    text.parse()
        .map_err(|e: toml_edit::TomlError| CalibrateError::Toml {
            origin: origin.to_string(),
            message: e.to_string(),
        })
}

/// Sets `[monitor]` keys in a monitor configuration text (comments kept).
pub(crate) fn with_monitor_keys(
    text: &str,
    origin: &str,
    keys: &[(&str, f64)],
) -> Result<String, CalibrateError> {
    let mut doc = parse_doc(text, origin)?;
    if doc.get("monitor").is_none() {
        doc["monitor"] = toml_edit::table();
    }
    for (k, v) in keys {
        doc["monitor"][*k] = toml_edit::value(*v);
    }
    Ok(doc.to_string())
}

/// Replaces the `[[model.modes]]` values in a throttle configuration text by the identified
/// ones (comments kept).
fn with_model(text: &str, origin: &str, id: &Identified) -> Result<String, CalibrateError> {
    let mut doc = parse_doc(text, origin)?;
    let modes = doc
        .get_mut("model")
        .and_then(|m| m.get_mut("modes"))
        .and_then(|m| m.as_array_of_tables_mut())
        .ok_or_else(|| CalibrateError::Toml {
            origin: origin.to_string(),
            message: "[[model.modes]]: expected an array of three tables".into(),
        })?;
    for (s, table) in modes.iter_mut().enumerate() {
        let Some(m) = id.params.modes.get(s) else {
            break;
        };
        let v = [m.a21, m.a22, m.a23, m.a32, m.a33, m.b, m.c1, m.c2, m.c3];
        for (k, x) in IDENTIFIED_KEYS.iter().zip(v) {
            table[*k] = toml_edit::value(x);
        }
    }
    Ok(doc.to_string())
}

/// Refuses a rate that asks to extrapolate more than [`MAX_EXTRAPOLATION`] times beyond
/// `hours` of data.
pub(crate) fn check_extrapolation(
    hours: f64,
    opts: &CalibrateOptions,
) -> Result<(), CalibrateError> {
    let ratio = 1.0 / (opts.false_alarms_per_hour * hours);
    if ratio <= MAX_EXTRAPOLATION {
        Ok(())
    } else {
        Err(CalibrateError::Extrapolation {
            rate: opts.false_alarms_per_hour,
            hours,
            ratio,
        })
    }
}

/// One test's threshold from its block maxima `(value, log index, block start s)`: the
/// extreme-value fit, its check, and the value a block maximum exceeds at the rate asked.
pub(crate) fn fit_threshold(
    test: &'static str,
    key: &'static str,
    maxima: &[(f64, usize, f64)],
    logs: &[PathBuf],
    hours: f64,
    opts: &CalibrateOptions,
) -> Result<TestCalibration, CalibrateError> {
    if maxima.is_empty() {
        return Err(CalibrateError::NoData(test));
    }
    let values: Vec<f64> = maxima.iter().map(|m| m.0).collect();
    let fit = GevFit::fit(&values).map_err(|source| CalibrateError::TooShort {
        test,
        hours,
        block_s: opts.block_s,
        source,
    })?;
    let (max, log, t_s) = maxima
        .iter()
        .copied()
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .unwrap_or((f64::NAN, 0, f64::NAN));
    let file = logs.get(log).cloned().unwrap_or_default();
    if !(fit.ppcc >= MIN_PPCC) {
        return Err(CalibrateError::BadFit {
            test,
            ppcc: fit.ppcc,
            max,
            file,
            t_s,
        });
    }
    let threshold = fit.threshold(opts.false_alarms_per_hour, opts.block_s);
    if max > threshold {
        return Err(CalibrateError::Exceeds {
            test,
            max,
            threshold,
            file,
            t_s,
            rate: opts.false_alarms_per_hour,
        });
    }
    Ok(TestCalibration {
        test,
        key,
        fit,
        max,
        threshold,
    })
}

/// Takes `value` at `(t_ns, block length ns, log index)` into the open block `slot`; a block
/// that ends (when the next one starts: only whole blocks count) goes into `maxima` as
/// `(its maximum, log index, start s)`. A value that is not finite is left out.
pub(crate) fn block_max(
    slot: &mut Option<(u64, f64)>,
    maxima: &mut Vec<(f64, usize, f64)>,
    (t_ns, block_ns, log): (u64, u64, usize),
    value: f64,
) {
    if !value.is_finite() {
        return;
    }
    match slot {
        Some((start, m)) if t_ns < *start + block_ns => *m = m.max(value),
        _ => {
            if let Some((start, m)) = slot.take() {
                maxima.push((m, log, start as f64 * 1e-9));
            }
            *slot = Some((t_ns, value));
        }
    }
}

/// A monitor configuration's text and origin: the file `path`, or the embedded `default`.
pub(crate) fn monitor_text(
    path: Option<&Path>,
    default: &str,
    default_origin: &str,
) -> Result<(String, String), CalibrateError> {
    match path {
        Some(p) => Ok((
            fdd_monitor::text_file::read_text(p)?,
            p.display().to_string(),
        )),
        None => Ok((default.to_string(), default_origin.to_string())),
    }
}

/// Refuses `file` when its ground truth had `fault` (name, onset s) active.
pub(crate) fn refuse_fault(
    file: &Path,
    fault: Option<(String, f64)>,
) -> Result<(), CalibrateError> {
    match fault {
        Some((fault, t_s)) => Err(CalibrateError::FaultInLog {
            file: file.to_path_buf(),
            fault,
            t_s,
        }),
        None => Ok(()),
    }
}

/// Replays one input (an MCAP log, or a scenario file simulated into a temporary log) through
/// `cfg` with `observer`.
pub(crate) fn replay_input(
    file: &Path,
    cfg: &RuntimeConfig,
    observer: &mut dyn ReplayObserver,
) -> Result<(), CalibrateError> {
    let opts = ReplayOptions::default();
    if file.extension().and_then(|e| e.to_str()) == Some("toml") {
        let tmp = tempfile::Builder::new()
            .prefix("fdd-calibrate-")
            .suffix(".mcap")
            .tempfile()
            .map_err(crate::evaluate::EvaluateError::Temp)?;
        // Scenario lengths were checked against `--allow-long` before the first pass
        // ([`calibrate_inputs`]).
        let sim = crate::simulate::SimulateOptions { allow_long: true };
        crate::simulate::simulate(&file.to_string_lossy(), tmp.path(), &sim).map_err(|source| {
            crate::evaluate::EvaluateError::Simulate {
                file: file.to_path_buf(),
                source: Box::new(source),
            }
        })?;
        replay_observed(tmp.path(), cfg, &opts, observer)?;
    } else {
        replay_observed(file, cfg, &opts, observer)?;
    }
    Ok(())
}

/// The runtime configuration `fdd calibrate` writes: the starting one (a file, or the embedded
/// default) with `[monitors] key = file` naming the calibrated monitor configuration beside it.
pub(crate) fn runtime_naming(
    base: &RuntimeConfig,
    key: &str,
    file: &str,
) -> Result<String, CalibrateError> {
    let runtime_text = match base.origin.as_str() {
        o if Path::new(o).is_file() => fdd_monitor::text_file::read_text(Path::new(o))?,
        _ => fdd_monitor::runtime::config::DEFAULT_RUNTIME_TOML.to_string(),
    };
    let mut doc = parse_doc(&runtime_text, &base.origin)?;
    if doc.get("monitors").is_none() {
        doc["monitors"] = toml_edit::table();
    }
    doc["monitors"][key] = toml_edit::value(file);
    Ok(doc.to_string())
}

/// Runs every log through the runtime of `cfg` with `collector`.
fn pass(
    logs: &[PathBuf],
    cfg: &RuntimeConfig,
    block_s: f64,
    gather: bool,
) -> Result<Collector, CalibrateError> {
    let mut c = Collector {
        block_ns: (block_s * 1e9) as u64,
        records: gather.then(Vec::new),
        ..Collector::default()
    };
    for (i, file) in logs.iter().enumerate() {
        c.log_index = i;
        c.file = file.clone();
        c.fault = None;
        replay_input(file, cfg, &mut c)?;
        c.flush();
        refuse_fault(file, c.fault.take())?;
    }
    Ok(c)
}

/// The monitor a calibration pass runs alone.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Only {
    Throttle,
    Intake,
    Turbo,
}

/// A runtime configuration in which `only` runs alone, reading `text` (written to `dir` as
/// `throttle.toml`, `intake.toml` or `turbo.toml`; a turbo file's parameter file must already
/// be in `dir`).
pub(crate) fn runtime_with_only(
    base: &RuntimeConfig,
    dir: &Path,
    text: &str,
    only: Only,
) -> Result<RuntimeConfig, CalibrateError> {
    let name = match only {
        Only::Throttle => "throttle.toml",
        Only::Intake => "intake.toml",
        Only::Turbo => "turbo.toml",
    };
    let path = dir.join(name);
    std::fs::write(&path, text).map_err(|source| CalibrateError::Write {
        file: path.clone(),
        source,
    })?;
    let mut cfg = base.clone();
    let m = &mut cfg.monitors;
    m.throttle = only == Only::Throttle;
    m.intake = only == Only::Intake;
    m.turbo = only == Only::Turbo;
    let slot = match only {
        Only::Throttle => &mut m.throttle_config,
        Only::Intake => &mut m.intake_config,
        Only::Turbo => &mut m.turbo_config,
    };
    *slot = Some(path);
    Ok(cfg)
}

pub(crate) fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

/// Calibrates the throttle monitor of `base` on `inputs` (see the [module documentation](self)).
pub fn calibrate(
    inputs: &[PathBuf],
    base: &RuntimeConfig,
    opts: &CalibrateOptions,
) -> Result<Calibration, CalibrateError> {
    let logs = expand_inputs(inputs)?;
    let (throttle_text, throttle_origin) = monitor_text(
        base.monitors.throttle_config.as_deref(),
        fdd_monitor::config::DEFAULT_THROTTLE_TOML,
        "config/throttle.toml",
    )?;
    let work = tempfile::tempdir().map_err(crate::evaluate::EvaluateError::Temp)?;
    let unreachable = [
        ("tps_nis_threshold", UNREACHABLE_NIS),
        ("tps_cusum_threshold", UNREACHABLE_CUSUM),
        ("watt_cusum_threshold", UNREACHABLE_CUSUM),
        ("tps_step_sigma", UNREACHABLE_NIS),
        ("watt_only_cusum_threshold", UNREACHABLE_CUSUM),
    ];

    // Pass 1: the noise levels, with wide bounds.
    let mut keys: Vec<(&str, f64)> = unreachable.to_vec();
    keys.extend([
        ("tps_noise_min_v", 1e-4),
        ("tps_noise_max_v", 1.0),
        ("wattmeter_noise_min_w", 1e-3),
        ("wattmeter_noise_max_w", 10.0),
    ]);
    let text = with_monitor_keys(&throttle_text, &throttle_origin, &keys)?;
    let cfg = runtime_with_only(base, work.path(), &text, Only::Throttle)?;
    // The per-log levels: the collector keeps the last of each log. With re-identification,
    // the first pass also gathers the raw signals, and the model error is measured again with
    // the identified model.
    let mut tps_levels = Vec::new();
    let mut watt_levels = Vec::new();
    let mut model_error = Vec::new();
    let mut records = Vec::new();
    let mut incomplete = 0;
    for log in &logs {
        let c = pass(std::slice::from_ref(log), &cfg, opts.block_s, opts.identify)?;
        tps_levels.push(c.noise.0);
        watt_levels.push(c.noise.1);
        model_error.extend(c.watt_lp_maxima);
        records.extend(c.records.into_iter().flatten());
        incomplete += c.incomplete;
    }
    let tps_noise_v = median(tps_levels);
    let wattmeter_noise_w = median(watt_levels);
    if !(tps_noise_v.is_finite() && wattmeter_noise_w.is_finite()) {
        return Err(CalibrateError::NoData("tps_noise_std_v"));
    }
    let mut throttle_text = throttle_text;
    let mut identified = None;
    if opts.identify {
        let total: usize = records.iter().map(Vec::len).sum();
        if incomplete as usize > total / 10 {
            return Err(CalibrateError::Unaligned { incomplete });
        }
        let start = fdd_monitor::config::ThrottleConfig::parse(&throttle_text, &throttle_origin)?;
        let settings = IdentifySettings {
            tps_var_v2: tps_noise_v * tps_noise_v,
            watt_var_w2: wattmeter_noise_w * wattmeter_noise_w,
            q_diag: start.wattmeter_ukf.q_diag,
            p0_diag: start.wattmeter_ukf.p0_diag,
            tps_v_per_deg: start.position_sensor.full_scale_v
                / start.position_sensor.full_scale_deg,
            ..IdentifySettings::default()
        };
        let slices: Vec<&[IdSample]> = records.iter().map(Vec::as_slice).collect();
        let id = identify(&slices, &start.model, &settings)?;
        drop(records);
        throttle_text = with_model(&throttle_text, &throttle_origin, &id)?;
        identified = Some(id);
        let text = with_monitor_keys(&throttle_text, &throttle_origin, &keys)?;
        let cfg = runtime_with_only(base, work.path(), &text, Only::Throttle)?;
        model_error.clear();
        for log in &logs {
            let c = pass(std::slice::from_ref(log), &cfg, opts.block_s, false)?;
            model_error.extend(c.watt_lp_maxima);
        }
    }
    // The dead band of the wattmeter test: the 90th percentile of the blocks' largest
    // low-passed residual (what model error alone reaches in most blocks).
    model_error.sort_by(f64::total_cmp);
    let watt_model_error_w = model_error
        .get(model_error.len() * 9 / 10)
        .copied()
        .unwrap_or(f64::NAN);
    if !watt_model_error_w.is_finite() {
        return Err(CalibrateError::NoData("wattmeter_cusum"));
    }

    // Pass 2: the statistics at those levels (bounds around them, as the calibrated
    // configuration will have).
    let noise_keys = [
        ("tps_noise_v", tps_noise_v),
        ("tps_noise_min_v", tps_noise_v),
        ("tps_noise_max_v", 3.0 * tps_noise_v),
        ("wattmeter_noise_w", wattmeter_noise_w),
        ("wattmeter_noise_min_w", 0.5 * wattmeter_noise_w),
        ("wattmeter_noise_max_w", 3.0 * wattmeter_noise_w),
        ("watt_model_error_w", watt_model_error_w),
    ];
    let mut keys: Vec<(&str, f64)> = unreachable.to_vec();
    keys.extend(noise_keys);
    let text = with_monitor_keys(&throttle_text, &throttle_origin, &keys)?;
    let cfg = runtime_with_only(base, work.path(), &text, Only::Throttle)?;
    let c = pass(&logs, &cfg, opts.block_s, false)?;
    let hours = c.total_ns as f64 * 1e-9 / 3600.0;
    check_extrapolation(hours, opts)?;
    let mut tests = Vec::new();
    for (i, (test, key)) in TESTS.iter().enumerate() {
        tests.push(fit_threshold(test, key, &c.maxima[i], &logs, hours, opts)?);
    }
    let mut keys: Vec<(&str, f64)> = noise_keys.to_vec();
    keys.extend(tests.iter().map(|t| (t.key, t.threshold)));
    // The wattmeter-only test takes the combined wattmeter test's threshold: it confirms that
    // test's verdict (and, after a TPS fault, needs its alarms to persist), and its block
    // maxima, with the filter re-seeded when it loses track, do not follow one extreme-value
    // law on a short log.
    if let Some(t) = tests.iter().find(|t| t.key == "watt_cusum_threshold") {
        keys.push(("watt_only_cusum_threshold", t.threshold));
    }
    let throttle_toml = with_monitor_keys(&throttle_text, &throttle_origin, &keys)?;
    let runtime_toml = runtime_naming(base, "throttle_config", "throttle.toml")?;
    Ok(Calibration {
        logs,
        hours,
        tps_noise_v,
        wattmeter_noise_w,
        watt_model_error_w,
        tests,
        throttle_toml,
        runtime_toml,
        identified,
    })
}

impl Calibration {
    /// Writes `dir/fdd.toml` (the runtime configuration, naming `throttle.toml` beside it) and
    /// `dir/throttle.toml`.
    pub fn write(&self, dir: &Path) -> Result<PathBuf, CalibrateError> {
        write_files(
            dir,
            &[
                ("throttle.toml", &self.throttle_toml),
                ("fdd.toml", &self.runtime_toml),
            ],
        )
    }

    /// The report `fdd calibrate` prints.
    pub fn render(&self, opts: &CalibrateOptions) -> String {
        use std::fmt::Write as _;
        let mut s = header(self.logs.len(), self.hours, opts);
        let _ = writeln!(
            s,
            "noise: TPS {:.2} mV, wattmeter {:.3} W (std, online estimate, median over the logs); wattmeter model error {:.3} W",
            1e3 * self.tps_noise_v,
            self.wattmeter_noise_w,
            self.watt_model_error_w
        );
        if let Some(id) = &self.identified {
            let _ = writeln!(
                s,
                "model re-identified ({} iterations{}; samples per mode {:?}): normalized innovation power {:.3} -> {:.3}; rms TPS {:.2} -> {:.2} mV, wattmeter {:.3} -> {:.3} W; spectral radius {:.4} {:.4} {:.4}",
                id.iterations,
                if id.converged { ", converged" } else { ", not converged" },
                id.samples_per_mode,
                id.cost_start,
                id.cost_end,
                1e3 * id.rms_start[0],
                1e3 * id.rms_end[0],
                id.rms_start[1],
                id.rms_end[1],
                id.spectral_radius[0],
                id.spectral_radius[1],
                id.spectral_radius[2],
            );
        }
        render_tests(&mut s, &self.tests);
        s
    }
}

/// The table of the calibrated tests: each fit and threshold.
fn render_tests(s: &mut String, tests: &[TestCalibration]) {
    use std::fmt::Write as _;
    let w = tests
        .iter()
        .map(|t| t.test.len())
        .max()
        .unwrap_or(0)
        .max(16);
    let _ = writeln!(
        *s,
        "{:<w$} {:>6} {:>10} {:>10} {:>7} {:>6} {:>10} {:>10}   key",
        "test", "blocks", "location", "scale", "shape", "PPCC", "max seen", "threshold"
    );
    for t in tests {
        let _ = writeln!(
            *s,
            "{:<w$} {:>6} {:>10.4} {:>10.4} {:>7.3} {:>6.3} {:>10.4} {:>10.4}   {}",
            t.test,
            t.fit.blocks,
            t.fit.location,
            t.fit.scale,
            t.fit.shape,
            t.fit.ppcc,
            t.max,
            t.threshold,
            t.key
        );
    }
}

/// The report's first line: the data and what was asked.
fn header(logs: usize, hours: f64, opts: &CalibrateOptions) -> String {
    format!(
        "{logs} logs, {hours:.2} h; blocks of {} s; {} false alarms per hour per test\n",
        opts.block_s, opts.false_alarms_per_hour
    )
}

/// A calibration of one monitor.
#[derive(Debug, Clone)]
pub enum Calibrated {
    Throttle(Box<Calibration>),
    Intake(Box<intake::IntakeCalibration>),
    Turbo(Box<turbo::TurboCalibration>),
}

impl Calibrated {
    /// Writes `dir/fdd.toml` (the runtime configuration, naming the monitor's file beside it)
    /// and that file (`throttle.toml` or `intake.toml`); returns the path of `fdd.toml`.
    pub fn write(&self, dir: &Path) -> Result<PathBuf, CalibrateError> {
        match self {
            Calibrated::Throttle(c) => c.write(dir),
            Calibrated::Intake(c) => write_files(
                dir,
                &[
                    ("intake.toml", &c.intake_toml),
                    ("fdd.toml", &c.runtime_toml),
                ],
            ),
            Calibrated::Turbo(c) => write_files(
                dir,
                &[
                    ("turbo.toml", &c.turbo_toml),
                    (c.params_name.as_str(), &c.params_toml),
                    ("fdd.toml", &c.runtime_toml),
                ],
            ),
        }
    }

    /// The report `fdd calibrate` prints.
    pub fn render(&self, opts: &CalibrateOptions) -> String {
        match self {
            Calibrated::Throttle(c) => c.render(opts),
            Calibrated::Intake(c) => {
                let mut s = header(c.logs.len(), c.hours, opts);
                c.render_body(&mut s);
                render_tests(&mut s, &c.tests);
                s
            }
            Calibrated::Turbo(c) => {
                // No false-alarm rate: the thresholds are a margin on the largest value seen.
                let mut s = format!(
                    "{} logs, {:.2} h; blocks of {} s\n",
                    c.logs.len(),
                    c.hours,
                    opts.block_s
                );
                c.render_body(&mut s);
                s
            }
        }
    }
}

/// Writes `files` (name, text) into `dir` (created); returns the path of `dir/fdd.toml`.
fn write_files(dir: &Path, files: &[(&str, &String)]) -> Result<PathBuf, CalibrateError> {
    std::fs::create_dir_all(dir).map_err(|source| CalibrateError::Write {
        file: dir.to_path_buf(),
        source,
    })?;
    for (name, text) in files {
        let p = dir.join(name);
        std::fs::write(&p, text).map_err(|source| CalibrateError::Write { file: p, source })?;
    }
    Ok(dir.join("fdd.toml"))
}

/// The monitor a calibration input is for: a scenario file's `monitor` key, or the monitor
/// that would run on a log (exactly one).
fn input_monitor(file: &Path, base: &RuntimeConfig) -> Result<String, CalibrateError> {
    let refuse = |message: String| CalibrateError::Monitor {
        file: file.to_path_buf(),
        message,
    };
    if file.extension().and_then(|e| e.to_str()) == Some("toml") {
        let text = fdd_monitor::text_file::read_text(file)?;
        let doc = parse_doc(&text, &file.display().to_string())?;
        return doc
            .get("monitor")
            .and_then(|m| m.as_str())
            .map(str::to_string)
            .ok_or_else(|| refuse("the scenario has no `monitor` key".into()));
    }
    let run = crate::replay::monitors_on_log(file, base)?;
    match run.as_slice() {
        [one] => Ok(one.clone()),
        _ => Err(refuse(format!(
            "calibrates one monitor at a time, and the log feeds {} ({}); name one with --monitor",
            run.len(),
            run.join(", ")
        ))),
    }
}

/// Calibrates `monitor` (`None`: the one the inputs are for) on `inputs` (fault-free logs,
/// scenario files or directories of either).
pub fn calibrate_inputs(
    inputs: &[PathBuf],
    base: &RuntimeConfig,
    opts: &CalibrateOptions,
    monitor: Option<&str>,
) -> Result<Calibrated, CalibrateError> {
    opts.check()?;
    let logs = expand_inputs(inputs)?;
    let sim = crate::simulate::SimulateOptions {
        allow_long: opts.allow_long,
    };
    for log in logs
        .iter()
        .filter(|l| l.extension().is_some_and(|e| e == "toml"))
    {
        crate::simulate::check_length(log, &sim).map_err(|source| {
            crate::evaluate::EvaluateError::Simulate {
                file: log.clone(),
                source: Box::new(source),
            }
        })?;
    }
    let monitor = match monitor {
        Some(m) => m.to_string(),
        None => {
            let mut found: Option<(String, PathBuf)> = None;
            for log in &logs {
                let m = input_monitor(log, base)?;
                match &found {
                    None => found = Some((m, log.clone())),
                    Some((first, first_log)) if *first != m => {
                        return Err(CalibrateError::Monitor {
                            file: log.clone(),
                            message: format!(
                                "is for the {m} monitor, {} for the {first} monitor; calibrate one monitor at a time",
                                first_log.display()
                            ),
                        });
                    }
                    Some(_) => {}
                }
            }
            found.map(|f| f.0).unwrap_or_else(|| "throttle".into())
        }
    };
    match monitor.as_str() {
        "throttle" => Ok(Calibrated::Throttle(Box::new(calibrate(
            &logs, base, opts,
        )?))),
        "intake" => Ok(Calibrated::Intake(Box::new(intake::calibrate(
            logs, base, opts,
        )?))),
        "turbo" => Ok(Calibrated::Turbo(Box::new(turbo::calibrate(
            logs, base, opts,
        )?))),
        other => Err(CalibrateError::UnknownMonitor(other.to_string())),
    }
}
