//! `fdd reproduce turbo`: the air-path observer paper's claims (seeds/004, REFERENCE §4) on the
//! real TSFS09 engine: the gain-scheduled observer on the committed model
//! (`config/turbo_tsfs09.toml`), run on the measured transients, judged against the sensors.
//!
//! # Protocol (fixed before any figure was looked at)
//!
//! - **Transients**: the four logs of `fixtures/data/real/liu-tsfs09/`. Two have the inputs the
//!   model needs (throttle) and the sensors the observer uses (`p_im`, air flow):
//!   `grupp1_airstep` (throttle 30 -> 20 -> 30 %, the paper's experiment) is the **tuning** log:
//!   every setting below that is taken from data comes from it; `grupp2_wastegate` (wastegate
//!   steps at a throttle of 26 %) is **held out**, and its figures are reported separately. The
//!   fuel-step and wastegate-step logs have no throttle position, so the model cannot be run on
//!   them.
//! - **Inputs** the logs do not have: the engine speed (constant in every log, not logged) is
//!   read off the engine map (model-free: at the log's initial `p_im`, each map speed line's air
//!   flow interpolated linearly in `p_im`, then the speed whose flow matches the log's initial
//!   air flow, [`speed_from_map`]); the wastegate of the airstep log (not logged) is the
//!   opening the model needs at the map's points around the log's initial operating point
//!   ([`LogSetting::wastegate_frac`]: the whole-model check solves it per point to match the
//!   measured boost), the rule `fdd fit turbo` uses when it fits the shaft's loss torque to the
//!   log's start. Without that loss the model made the map's 109-113 kPa of boost at
//!   1,050-1,300 rpm and 86 kPa with its wastegate a quarter open, and with it closed (the
//!   paper's choice) its stationary point at the log's start had 125 kPa of boost, a manifold
//!   pressure 10 kPa above the sensor's and a turbo speed 1.7 times the measured one; with the
//!   fitted loss the map's opening there is about closed (0.001); lambda 1 where not logged;
//!   ambient pressure the map's fitted one, ambient temperature 298 K (the compressor map's
//!   reference; the logs have no ambient temperature).
//! - **Sensors**: `p_im` and the air flow (the transients log no boost pressure); the turbo
//!   speed is measured but kept out of the observer, to judge its estimate.
//! - **Noise**: `R` = each sensor's variance about its mean over the tuning log's stationary
//!   start (before the first throttle change), floored at [`R_FLOOR_REL`] of the mean squared;
//!   `Q` from the model's stationary error at the engine-map points
//!   ([`fdd_estimators::models::turbo::observer::design::state_noise_from_map`]); the turbo
//!   speed's entry the RMS over the tuning log's stationary segments of the model's stationary
//!   speed at the segment's inputs against the measured mean there (the shaft's loss torque is
//!   fitted to the first segment, so that one alone would say the model is exact).
//! - **Gains** on [`GRID_SPEEDS_RPM`] x [`GRID_PRESSURES_KPA`], bilinear (the paper's nearest
//!   node for comparison); 80 Hz (the logs' rate).
//! - **Figures** per log: the turbo speed estimate's RMS error in % of the measured mean; the
//!   air-flow estimate against the sensor (RMS difference in % of the sensor's mean, and its
//!   noise against the sensor's on the stationary segments); the
//!   `p_im` estimate's noise against the sensor's (standard deviations about a straight line on
//!   the stationary segments: from 1 s after an input step to the next); its lag behind the
//!   sensor (the cross-correlation's peak, sub-sample by a parabola, positive = estimate
//!   later); the stationary `p_im` error (mean of estimate minus sensor on the stationary
//!   segments) with the model's volumetric efficiency 5 % low, without and with `dC_eta_vol`,
//!   and the share the state removes.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use fdd_estimators::models::turbo::fit::check::check_engine_map;
use fdd_estimators::models::turbo::fit::components::fit_air_filter;
use fdd_estimators::models::turbo::fit::map_lookup::speed_from_map;
use fdd_estimators::models::turbo::fit::{EnginePoint, FitError, FitOptions, ShaftAnchor};
use fdd_estimators::models::turbo::observer::design::{
    design_gains, state_noise_from_map, Conditions, DesignError, DesignOptions, NoiseSample,
};
use fdd_estimators::models::turbo::observer::{GainTable, Interpolation, Sensor, TurboObserver};
use fdd_estimators::models::turbo::{TurboError, TurboInput, TurboModel, TurboParams, X_OMEGA_T};
use fdd_estimators::ParamError;
use fdd_monitor::log::{LogError, LogReader};
use nalgebra::SVector;
use thiserror::Error;

use crate::fit::{load_params, read_data, FitIoError};

/// Grid of engine speeds of the gain table (rpm): the map's range, every 500 rpm.
pub const GRID_SPEEDS_RPM: [f64; 8] = [
    800.0, 1300.0, 1800.0, 2300.0, 2800.0, 3300.0, 3800.0, 4300.0,
];
/// Grid of intake manifold pressures (kPa): the map's range.
pub const GRID_PRESSURES_KPA: [f64; 11] = [
    20.0, 35.0, 50.0, 65.0, 80.0, 95.0, 110.0, 130.0, 150.0, 170.0, 190.0,
];
/// Floor of a sensor's noise standard deviation relative to its mean (0.1 %).
pub const R_FLOOR_REL: f64 = 1e-3;
/// The volumetric-efficiency error of the `dC_eta_vol` experiment (the model's factor times
/// 0.95).
pub const VE_ERROR: f64 = 0.95;
/// Ambient temperature of the transients (K): the compressor map's reference.
pub const AMBIENT_TEMPERATURE_K: f64 = 298.0;
/// Time after an input step before a segment counts as stationary (s).
pub const SETTLE_S: f64 = 1.0;
/// Shortest stationary segment (s).
pub const MIN_SEGMENT_S: f64 = 1.0;
/// Window around a throttle step in which the lag is timed: (before, after) (s).
pub const LAG_WINDOW_S: (f64, f64) = (0.5, 2.0);
/// The observer's sample time: the logs' 80 Hz (s).
pub const DT_S: f64 = 0.0125;

/// The tuning log and the held-out one.
pub const TUNING_LOG: &str = "grupp1_airstep.mcap";
/// See [`TUNING_LOG`].
pub const HELD_OUT_LOG: &str = "grupp2_wastegate.mcap";

/// A failure of the reproduction.
#[derive(Debug, Error)]
pub enum TurboReproError {
    /// Reading the map or the parameters.
    #[error(transparent)]
    Io(#[from] FitIoError),
    /// Reading a log.
    #[error(transparent)]
    Log(#[from] LogError),
    /// A log lacks a topic.
    #[error("{file}: no messages on topic `{topic}` (field `{field}`)")]
    MissingTopic {
        /// The log.
        file: PathBuf,
        /// The topic.
        topic: &'static str,
        /// The field.
        field: &'static str,
    },
    /// A log has too few samples or no stationary start.
    #[error("{file}: {what}")]
    Log2 {
        /// The log.
        file: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// The model refused something.
    #[error("turbo model: {0}")]
    Model(#[from] TurboError),
    /// A parameter.
    #[error("turbo model: {0}")]
    Param(#[from] ParamError),
    /// The map check.
    #[error("engine map check: {0}")]
    Fit(#[from] FitError),
    /// The gain design.
    #[error(transparent)]
    Design(#[from] DesignError),
    /// Writing a series file.
    #[error("{file}: {source}")]
    Write {
        /// The file.
        file: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

/// One transient log's signals on a common time base.
#[derive(Debug, Clone, Default)]
pub struct Transient {
    /// File.
    pub file: PathBuf,
    /// Time (s).
    pub t: Vec<f64>,
    /// Throttle (%).
    pub throttle_pct: Vec<f64>,
    /// Intake manifold pressure (Pa).
    pub p_im_pa: Vec<f64>,
    /// Air flow (kg/s).
    pub maf_kg_s: Vec<f64>,
    /// Turbo speed (rad/s).
    pub turbo_speed_rad_s: Vec<f64>,
    /// Wastegate (0..1), if logged.
    pub wastegate: Option<Vec<f64>>,
    /// Lambda, if logged.
    pub lambda: Option<Vec<f64>>,
}

const TOPICS: [(&str, &str); 6] = [
    ("/turbo/throttle", "position_pct"),
    ("/turbo/p_im", "pressure_pa"),
    ("/turbo/maf", "flow_kg_s"),
    ("/turbo/turbo_speed", "speed_rad_s"),
    ("/turbo/wastegate", "position"),
    ("/turbo/lambda", "lambda"),
];

/// Reads a transient log: every message of the six topics, by log time; a row is kept where
/// the four required topics all have a value.
pub fn read_transient(path: &Path) -> Result<Transient, TurboReproError> {
    let reader = LogReader::open(path)?;
    let mut rows: BTreeMap<u64, [Option<f64>; 6]> = BTreeMap::new();
    for msg in reader {
        let msg = msg?;
        if let Some(k) = TOPICS.iter().position(|(t, _)| *t == &*msg.topic) {
            let v = msg.field_f64(TOPICS[k].1)?;
            rows.entry(msg.log_time_ns).or_insert([None; 6])[k] = Some(v);
        }
    }
    let mut tr = Transient {
        file: path.to_path_buf(),
        ..Default::default()
    };
    let has = |k: usize| rows.values().any(|r| r[k].is_some());
    for (k, (topic, field)) in TOPICS.iter().enumerate().take(4) {
        if !has(k) {
            return Err(TurboReproError::MissingTopic {
                file: path.to_path_buf(),
                topic,
                field,
            });
        }
    }
    let (has_wg, has_lambda) = (has(4), has(5));
    let mut wg = Vec::new();
    let mut lambda = Vec::new();
    for (t, r) in &rows {
        let (Some(a), Some(p), Some(w), Some(n)) = (r[0], r[1], r[2], r[3]) else {
            continue;
        };
        tr.t.push(*t as f64 * 1e-9);
        tr.throttle_pct.push(a);
        tr.p_im_pa.push(p);
        tr.maf_kg_s.push(w);
        tr.turbo_speed_rad_s.push(n);
        wg.push(r[4].unwrap_or(f64::NAN));
        lambda.push(r[5].unwrap_or(f64::NAN));
    }
    if tr.t.len() < 100 {
        return Err(TurboReproError::Log2 {
            file: path.to_path_buf(),
            what: format!("{} complete rows, at least 100 needed", tr.t.len()),
        });
    }
    tr.wastegate = has_wg.then_some(wg);
    tr.lambda = has_lambda.then_some(lambda);
    Ok(tr)
}

/// Stationary segments `[start, end)` (sample indices): from [`SETTLE_S`] after an input step
/// (throttle by more than 0.5 %-points or wastegate by more than 2 %-points between samples,
/// or the log's start) to the next step, at least [`MIN_SEGMENT_S`] long. The log's start counts
/// as settled.
pub fn stationary_segments(tr: &Transient) -> Vec<(usize, usize)> {
    let n = tr.t.len();
    let mut steps = vec![0usize];
    for i in 1..n {
        let da = (tr.throttle_pct[i] - tr.throttle_pct[i - 1]).abs() > 0.5;
        let dw = tr
            .wastegate
            .as_ref()
            .is_some_and(|w| (w[i] - w[i - 1]).abs() > 0.02);
        if da || dw {
            steps.push(i);
        }
    }
    steps.push(n);
    let mut out = Vec::new();
    for (k, w) in steps.windows(2).enumerate() {
        let settle = if k == 0 { 0.0 } else { SETTLE_S };
        let t0 = tr.t[w[0].min(n - 1)] + settle;
        let start = w[0] + tr.t[w[0]..w[1]].partition_point(|&t| t < t0);
        let end = w[1];
        if start < end && tr.t[end - 1] - tr.t[start] >= MIN_SEGMENT_S {
            out.push((start, end));
        }
    }
    // Merge steps closer than a sample apart (a ramp): segments never overlap by construction.
    out
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Standard deviation about the least-squares line through `(t, v)`.
fn detrended_std(t: &[f64], v: &[f64]) -> f64 {
    let (mt, mv) = (mean(t), mean(v));
    let stt: f64 = t.iter().map(|a| (a - mt).powi(2)).sum();
    let stv: f64 = t.iter().zip(v).map(|(a, b)| (a - mt) * (b - mv)).sum();
    let slope = if stt > 0.0 { stv / stt } else { 0.0 };
    let ss: f64 = t
        .iter()
        .zip(v)
        .map(|(a, b)| (b - mv - slope * (a - mt)).powi(2))
        .sum();
    (ss / t.len().max(2) as f64).sqrt()
}

/// Lag of `est` behind `sensor` in samples: the peak of their cross-correlation (means
/// removed) over -8..8 samples, refined by a parabola through the peak and its neighbours.
/// `None` if the peak lies on the edge of that range (no transient to time).
pub fn lag_samples(sensor: &[f64], est: &[f64]) -> Option<f64> {
    let (ms, me) = (mean(sensor), mean(est));
    let n = sensor.len().min(est.len()) as isize;
    let xc = |lag: isize| -> f64 {
        let mut s = 0.0;
        for i in 0..n {
            let j = i - lag;
            if j >= 0 && j < n {
                s += (est[i as usize] - me) * (sensor[j as usize] - ms);
            }
        }
        s
    };
    let lags: Vec<(isize, f64)> = (-8..=8).map(|l| (l, xc(l))).collect();
    let k = lags
        .iter()
        .enumerate()
        .max_by(|a, b| a.1 .1.total_cmp(&b.1 .1))
        .map(|(k, _)| k)?;
    if k == 0 || k + 1 == lags.len() {
        return None;
    }
    let (a, b, c) = (lags[k - 1].1, lags[k].1, lags[k + 1].1);
    let d = a - 2.0 * b + c;
    Some(lags[k].0 as f64 + if d != 0.0 { 0.5 * (a - c) / d } else { 0.0 })
}

/// Windows around the throttle steps (from [`LAG_WINDOW_S`]`.0` before a step of more than
/// 0.5 %-points between samples to `.1` after it), where a lag can be timed.
pub fn throttle_step_windows(tr: &Transient) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = Vec::new();
    for i in 1..tr.t.len() {
        if (tr.throttle_pct[i] - tr.throttle_pct[i - 1]).abs() > 0.5 {
            let a = tr.t.partition_point(|&t| t < tr.t[i] - LAG_WINDOW_S.0);
            let b = tr.t.partition_point(|&t| t <= tr.t[i] + LAG_WINDOW_S.1);
            match out.last_mut() {
                Some(last) if a <= last.1 => last.1 = last.1.max(b),
                _ => out.push((a, b)),
            }
        }
    }
    out
}

/// Lag over the throttle-step windows (the windows concatenated).
fn step_lag(sensor: &[f64], est: &[f64], windows: &[(usize, usize)]) -> Option<f64> {
    if windows.is_empty() {
        return None;
    }
    let mut s = Vec::new();
    let mut e = Vec::new();
    for &(a, b) in windows {
        s.extend_from_slice(&sensor[a..b]);
        e.extend_from_slice(&est[a..b]);
    }
    lag_samples(&s, &e)
}

/// Lambda at sample `i`: logged, or 1 where not logged or not finite.
fn transient_lambda(tr: &Transient, i: usize) -> f64 {
    tr.lambda.as_ref().map_or(1.0, |l| {
        if l[i].is_finite() {
            l[i].clamp(0.5, 3.0)
        } else {
            1.0
        }
    })
}

/// What a transient's inputs lack, decided once per log (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogSetting {
    /// Engine speed (rad/s), read off the map ([`speed_from_map`]).
    pub engine_speed_rad_s: f64,
    /// Ambient pressure (Pa): the map's air-filter fit.
    pub ambient_pa: f64,
    /// Wastegate opening where the log has none: the map's at the log's initial point
    /// ([`fdd_estimators::models::turbo::fit::map_lookup::wastegate_from_map`]).
    pub wastegate_frac: f64,
}

/// The inputs the model gets at sample `i` of a transient: the logged throttle, wastegate
/// (the setting's where not logged) and lambda (1 where not logged, or not finite), the
/// setting's engine speed and ambient pressure, and [`AMBIENT_TEMPERATURE_K`].
pub fn transient_input(tr: &Transient, i: usize, set: &LogSetting) -> TurboInput {
    let wg = tr
        .wastegate
        .as_ref()
        .map_or(set.wastegate_frac, |w| w[i].clamp(0.0, 1.0));
    let lambda = transient_lambda(tr, i);
    TurboInput {
        throttle_pct: tr.throttle_pct[i].clamp(0.0, 100.0),
        engine_speed_rad_s: set.engine_speed_rad_s,
        wastegate_frac: wg,
        lambda,
        ambient_pressure_pa: set.ambient_pa,
        ambient_temperature_k: AMBIENT_TEMPERATURE_K,
    }
}

/// One observer run over a log.
#[derive(Debug, Clone, Default)]
pub struct Run {
    /// `p_im` estimate (Pa).
    pub p_im_pa: Vec<f64>,
    /// Turbo speed estimate (rad/s).
    pub turbo_speed_rad_s: Vec<f64>,
    /// `dC_eta_vol`.
    pub dc: Vec<f64>,
    /// Air flow estimate (kg/s).
    pub maf_kg_s: Vec<f64>,
}

fn run_observer(
    model: &TurboModel,
    table: &GainTable<2>,
    mode: Interpolation,
    augmented: bool,
    tr: &Transient,
    set: &LogSetting,
) -> Result<Run, TurboReproError> {
    let mut obs = TurboObserver::new(
        model.clone(),
        DT_S,
        [Sensor::PIm, Sensor::Maf],
        table.clone(),
        mode,
        augmented,
    )?;
    obs.reset_stationary(&transient_input(tr, 0, set))?;
    let mut run = Run::default();
    for i in 0..tr.t.len() {
        let u = transient_input(tr, i, set);
        let y = SVector::<f64, 2>::new(tr.p_im_pa[i], tr.maf_kg_s[i]);
        let s = obs.update(&u, &y)?;
        run.p_im_pa.push(s.signals.p_im_pa);
        run.turbo_speed_rad_s.push(obs.state()[X_OMEGA_T]);
        run.dc.push(obs.state()[13]);
        run.maf_kg_s.push(s.signals.w_af_kg_s);
    }
    Ok(run)
}

/// Figures of one log.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct LogFigures {
    /// Engine speed used (rpm).
    pub engine_speed_rpm: f64,
    /// The map's wastegate opening used where the log has none.
    pub wastegate_frac: Option<f64>,
    /// Turbo speed estimate RMS error, % of the measured mean.
    pub turbo_speed_rms_pct: f64,
    /// Same for the model alone (no feedback).
    pub turbo_speed_rms_pct_open_loop: f64,
    /// `p_im` sensor noise std on the stationary segments (Pa).
    pub p_im_sensor_noise_pa: f64,
    /// `p_im` estimate noise std on the same segments (Pa).
    pub p_im_estimate_noise_pa: f64,
    /// Their ratio (%).
    pub p_im_noise_ratio_pct: f64,
    /// Air-flow estimate against the sensor: RMS difference, % of the sensor's mean.
    pub maf_rms_pct: f64,
    /// Air-flow estimate noise std over the sensor's on the stationary segments (%).
    pub maf_noise_ratio_pct: f64,
    /// Lag of the estimate behind the sensor around the throttle steps (samples of 12.5 ms;
    /// None without a throttle step).
    pub p_im_lag_samples: Option<f64>,
    /// Same figures with the nearest-node gains: noise ratio (%).
    pub nearest_noise_ratio_pct: f64,
    /// Nearest-node lag (samples).
    pub nearest_lag_samples: Option<f64>,
    /// Nearest-node turbo speed RMS (%).
    pub nearest_turbo_speed_rms_pct: f64,
    /// Stationary `p_im` error, model VE 5 % low, without `dC_eta_vol` (Pa, mean over the
    /// stationary segments of estimate minus sensor).
    pub ve_error_plain_pa: f64,
    /// The same with `dC_eta_vol`.
    pub ve_error_augmented_pa: f64,
    /// Share of the error the state removes (%).
    pub ve_error_removed_pct: f64,
    /// Stationary segments used.
    pub segments: usize,
}

/// The report.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TurboReport {
    /// Ambient pressure (Pa) from the map's air filter fit.
    pub ambient_pressure_pa: f64,
    /// Measurement noise std (Pa, kg/s) from the tuning log.
    pub r_std: [f64; 2],
    /// Turbo-speed state noise (rad/s).
    pub turbo_speed_q_rad_s: f64,
    /// Largest closed-loop spectral radius over the grid.
    pub worst_closed_loop_radius: f64,
    /// Tuning log.
    pub tuning: LogFigures,
    /// Held-out log.
    pub held_out: LogFigures,
}

/// Settings.
#[derive(Debug, Clone)]
pub struct TurboSettings {
    /// Parameter file.
    pub params: PathBuf,
    /// TSFS09 data directory (map CSVs and transient MCAPs).
    pub data: PathBuf,
    /// If set, a CSV per log with every sample's sensors and estimates is written here.
    pub series: Option<PathBuf>,
}

fn stationary_mean_error(est: &[f64], sensor: &[f64], segs: &[(usize, usize)]) -> f64 {
    let mut s = 0.0;
    let mut n = 0usize;
    for &(a, b) in segs {
        for i in a..b {
            s += est[i] - sensor[i];
            n += 1;
        }
    }
    s / n.max(1) as f64
}

fn pooled_noise(t: &[f64], v: &[f64], segs: &[(usize, usize)]) -> f64 {
    let mut ss = 0.0;
    let mut n = 0usize;
    for &(a, b) in segs {
        let s = detrended_std(&t[a..b], &v[a..b]);
        ss += s * s * (b - a) as f64;
        n += b - a;
    }
    (ss / n.max(1) as f64).sqrt()
}

fn rms_pct(est: &[f64], meas: &[f64]) -> f64 {
    let e: f64 = est
        .iter()
        .zip(meas)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>();
    100.0 * (e / est.len() as f64).sqrt() / mean(meas)
}

/// The paper's state noise on the TSFS09 engine, as this reproduction and `fdd fit
/// turbo-gains --map` both take it: the model's stationary error at every engine-map point
/// (ambient pressure from the air filter fit on the training points), with the turbo speed's
/// entry from the tuning transient's stationary start (the map has no turbo speed): the
/// model's stationary speed at the start's inputs against the measured mean there.
#[derive(Debug, Clone)]
pub struct MapNoise {
    /// The engine map's points.
    pub engine: Vec<EnginePoint>,
    /// Ambient pressure (Pa) from the air filter fit.
    pub ambient_pressure_pa: f64,
    /// The state noise per map point.
    pub noise: Vec<NoiseSample>,
    /// The tuning log.
    pub tuning: Transient,
    /// Its stationary start (sample indices).
    pub stationary_start: (usize, usize),
    /// The map's points the fit was trained on (every 5th held out).
    pub training: Vec<EnginePoint>,
    /// Its setting (engine speed read off the map, the map's wastegate).
    pub tuning_setting: LogSetting,
    /// The turbo speed's state-noise entry (rad/s).
    pub turbo_speed_error_rad_s: f64,
}

/// The engine speed of a transient read off the map ([`speed_from_map`]), or an error naming
/// the log and its initial point.
fn transient_speed(engine: &[EnginePoint], tr: &Transient) -> Result<f64, TurboReproError> {
    speed_from_map(engine, tr.p_im_pa[0], tr.maf_kg_s[0]).ok_or_else(|| outside_map(tr))
}

fn outside_map(tr: &Transient) -> TurboReproError {
    TurboReproError::Log2 {
        file: tr.file.clone(),
        what: format!(
            "initial p_im {:.0} Pa and air flow {:.4} kg/s lie outside the engine map's speed lines",
            tr.p_im_pa[0], tr.maf_kg_s[0]
        ),
    }
}

/// A transient's setting: its engine speed read off the `engine` map, the ambient pressure,
/// and, if it logs no wastegate, the opening the model needs at the `training` map points
/// around its initial operating point (their whole-model check with `params`,
/// [`ShaftAnchor::wastegate`]: what `fdd fit turbo` takes at the same point).
fn transient_setting(
    params: &TurboParams,
    engine: &[EnginePoint],
    training: &[EnginePoint],
    tr: &Transient,
    ambient_pa: f64,
) -> Result<LogSetting, TurboReproError> {
    let anchor = anchor_of(engine, tr, (0, 1))?;
    let wastegate_frac = anchor.wastegate(params, training, ambient_pa, &FitOptions::tsfs09())?;
    Ok(LogSetting {
        engine_speed_rad_s: anchor.engine_speed_rad_s,
        ambient_pa,
        wastegate_frac,
    })
}

/// The anchor of a log's stretch `[a, b)`: the inputs of its first sample and the measured
/// turbo speed's mean over the stretch.
fn anchor_of(
    engine: &[EnginePoint],
    tr: &Transient,
    (a, b): (usize, usize),
) -> Result<ShaftAnchor, TurboReproError> {
    let speed = transient_speed(engine, tr)?;
    Ok(ShaftAnchor {
        throttle_pct: tr.throttle_pct[a].clamp(0.0, 100.0),
        engine_speed_rad_s: speed,
        p_im_pa: tr.p_im_pa[a],
        wastegate_frac: tr.wastegate.as_ref().map(|w| w[a].clamp(0.0, 1.0)),
        lambda: transient_lambda(tr, a),
        ambient_temperature_k: AMBIENT_TEMPERATURE_K,
        turbo_speed_rad_s: mean(&tr.turbo_speed_rad_s[a..b]),
    })
}

/// The tuning log's stationary start (before its first input step) as the shaft fit's anchor
/// ([`fdd_estimators::models::turbo::fit::shaft`]): the inputs of its first sample, as the
/// observer here starts from them ([`transient_input`]: lambda 1, engine speed read off the
/// `engine` map, no wastegate logged so the map's), and the measured turbo speed's mean over
/// the stretch. The fit reads the map's wastegate from its training points, as
/// the reproduction does for a log without a wastegate.
pub fn shaft_anchor(dir: &Path, engine: &[EnginePoint]) -> Result<ShaftAnchor, TurboReproError> {
    let tuning = read_transient(&dir.join(TUNING_LOG))?;
    let start = stationary_start(&tuning)?;
    anchor_of(engine, &tuning, start)
}

/// The stationary start of a log: its first stationary segment if it begins at sample 0.
fn stationary_start(tr: &Transient) -> Result<(usize, usize), TurboReproError> {
    stationary_segments(tr)
        .first()
        .filter(|(a, _)| *a == 0)
        .copied()
        .ok_or_else(|| TurboReproError::Log2 {
            file: tr.file.clone(),
            what: "no stationary start before the first input step".into(),
        })
}

/// The turbo speed's state noise (rad/s): the RMS over the tuning log's stationary segments
/// of the model's stationary turbo speed at each segment's inputs minus the measured mean
/// there. (The shaft's loss torque is fitted to the first segment, so one segment alone would say
/// the model is exact.)
fn turbo_speed_noise(
    model: &TurboModel,
    tr: &Transient,
    set: &LogSetting,
) -> Result<f64, TurboReproError> {
    let mut errors = Vec::new();
    for (a, b) in stationary_segments(tr) {
        let st = model.stationary_point(&transient_input(tr, a, set), None)?;
        errors.push(st.state[X_OMEGA_T] - mean(&tr.turbo_speed_rad_s[a..b]));
    }
    if errors.is_empty() {
        return Err(TurboReproError::Log2 {
            file: tr.file.clone(),
            what: "no stationary segment".into(),
        });
    }
    Ok((errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt())
}

/// See [`MapNoise`]; `dir` is the TSFS09 data directory.
pub fn map_noise(
    model: &TurboModel,
    params: &TurboParams,
    dir: &Path,
) -> Result<MapNoise, TurboReproError> {
    let data = read_data(dir)?;
    let opts = FitOptions::tsfs09();
    let training: Vec<EnginePoint> = data
        .engine
        .iter()
        .enumerate()
        .filter(|(i, _)| !opts.is_held_out(*i))
        .map(|(_, p)| *p)
        .collect();
    let ambient = fit_air_filter(&training, params)?.ambient_pressure_pa.value;
    let check = check_engine_map(params, &data.engine, ambient, &opts)?;
    let tuning = read_transient(&dir.join(TUNING_LOG))?;
    let (a0, b0) = stationary_start(&tuning)?;
    let setting = transient_setting(params, &data.engine, &training, &tuning, ambient)?;
    let q_speed = turbo_speed_noise(model, &tuning, &setting)?;
    let noise = state_noise_from_map(model, &data.engine, &check, q_speed);
    Ok(MapNoise {
        engine: data.engine,
        ambient_pressure_pa: ambient,
        noise,
        tuning,
        stationary_start: (a0, b0),
        training,
        tuning_setting: setting,
        turbo_speed_error_rad_s: q_speed,
    })
}

/// Runs the reproduction.
pub fn run(s: &TurboSettings) -> Result<TurboReport, TurboReproError> {
    let params: TurboParams = load_params(&s.params)?;
    let model = TurboModel::new(params.clone())?;
    let MapNoise {
        engine,
        ambient_pressure_pa: ambient,
        noise,
        tuning,
        stationary_start: (a0, b0),
        training,
        tuning_setting,
        turbo_speed_error_rad_s: q_speed,
    } = map_noise(&model, &params, &s.data)?;
    let held = read_transient(&s.data.join(HELD_OUT_LOG))?;
    // R from the tuning log's stationary start.
    let r_std: [f64; 2] = [&tuning.p_im_pa, &tuning.maf_kg_s].map(|v| {
        let seg = &v[a0..b0];
        let m = mean(seg);
        let sd = detrended_std(&tuning.t[a0..b0], seg);
        sd.max(R_FLOOR_REL * m.abs())
    });
    let held_setting = transient_setting(&params, &engine, &training, &held, ambient)?;
    let design_opts = DesignOptions {
        dt_s: DT_S,
        sensors: [Sensor::PIm, Sensor::Maf],
        r: r_std.map(|v| v * v),
        speeds_rad_s: GRID_SPEEDS_RPM
            .iter()
            .map(|r| r * std::f64::consts::TAU / 60.0)
            .collect(),
        pressures_pa: GRID_PRESSURES_KPA.iter().map(|p| p * 1e3).collect(),
        conditions: Conditions {
            ambient_pressure_pa: ambient,
            ambient_temperature_k: AMBIENT_TEMPERATURE_K,
            lambda: 1.0,
        },
    };
    let design = design_gains(&model, &design_opts, &noise)?;
    let worst = design
        .nodes
        .iter()
        .map(|n| n.closed_loop_radius)
        .fold(0.0, f64::max);

    let mut ve_params = params.clone();
    ve_params.vol_eff_factor *= VE_ERROR;
    let ve_model = TurboModel::new(ve_params)?;
    // The same gains for the perturbed model: the design is a property of the nominal model.
    let figures = |tr: &Transient, set: &LogSetting| -> Result<LogFigures, TurboReproError> {
        let segs = stationary_segments(tr);
        let windows = throttle_step_windows(tr);
        let bil = run_observer(
            &model,
            &design.table,
            Interpolation::Bilinear,
            true,
            tr,
            set,
        )?;
        let near = run_observer(&model, &design.table, Interpolation::Nearest, true, tr, set)?;
        let open = open_loop(&model, tr, set)?;
        let plain = run_observer(
            &ve_model,
            &design.table,
            Interpolation::Bilinear,
            false,
            tr,
            set,
        )?;
        let aug = run_observer(
            &ve_model,
            &design.table,
            Interpolation::Bilinear,
            true,
            tr,
            set,
        )?;
        let sensor_noise = pooled_noise(&tr.t, &tr.p_im_pa, &segs);
        let maf_sensor_noise = pooled_noise(&tr.t, &tr.maf_kg_s, &segs);
        let maf_est_noise = pooled_noise(&tr.t, &bil.maf_kg_s, &segs);
        let est_noise = pooled_noise(&tr.t, &bil.p_im_pa, &segs);
        let near_noise = pooled_noise(&tr.t, &near.p_im_pa, &segs);
        let nom_plain = run_observer(
            &model,
            &design.table,
            Interpolation::Bilinear,
            false,
            tr,
            set,
        )?;
        let e_plain = stationary_mean_error(&plain.p_im_pa, &nom_plain.p_im_pa, &segs);
        let e_aug = stationary_mean_error(&aug.p_im_pa, &bil.p_im_pa, &segs);
        if let Some(dir) = &s.series {
            write_series(dir, tr, &bil, &open, &plain, &aug)?;
        }
        Ok(LogFigures {
            engine_speed_rpm: set.engine_speed_rad_s * 60.0 / std::f64::consts::TAU,
            wastegate_frac: tr.wastegate.is_none().then_some(set.wastegate_frac),
            turbo_speed_rms_pct: rms_pct(&bil.turbo_speed_rad_s, &tr.turbo_speed_rad_s),
            turbo_speed_rms_pct_open_loop: rms_pct(&open, &tr.turbo_speed_rad_s),
            p_im_sensor_noise_pa: sensor_noise,
            p_im_estimate_noise_pa: est_noise,
            p_im_noise_ratio_pct: 100.0 * est_noise / sensor_noise,
            maf_rms_pct: rms_pct(&bil.maf_kg_s, &tr.maf_kg_s),
            maf_noise_ratio_pct: 100.0 * maf_est_noise / maf_sensor_noise,
            p_im_lag_samples: step_lag(&tr.p_im_pa, &bil.p_im_pa, &windows),
            nearest_noise_ratio_pct: 100.0 * near_noise / sensor_noise,
            nearest_lag_samples: step_lag(&tr.p_im_pa, &near.p_im_pa, &windows),
            nearest_turbo_speed_rms_pct: rms_pct(&near.turbo_speed_rad_s, &tr.turbo_speed_rad_s),
            ve_error_plain_pa: e_plain,
            ve_error_augmented_pa: e_aug,
            ve_error_removed_pct: 100.0 * (1.0 - e_aug.abs() / e_plain.abs()),
            segments: segs.len(),
        })
    };
    Ok(TurboReport {
        ambient_pressure_pa: ambient,
        r_std,
        turbo_speed_q_rad_s: q_speed,
        worst_closed_loop_radius: worst,
        tuning: figures(&tuning, &tuning_setting)?,
        held_out: figures(&held, &held_setting)?,
    })
}

fn write_series(
    dir: &Path,
    tr: &Transient,
    bil: &Run,
    open: &[f64],
    plain: &Run,
    aug: &Run,
) -> Result<(), TurboReproError> {
    use std::fmt::Write;
    let stem = tr
        .file
        .file_stem()
        .map_or_else(|| "log".into(), |s| s.to_string_lossy().into_owned());
    std::fs::create_dir_all(dir).map_err(|source| TurboReproError::Write {
        file: dir.to_path_buf(),
        source,
    })?;
    let path = dir.join(format!("{stem}_observer.csv"));
    let mut text = String::from(
        "t_s,throttle_pct,p_im_sensor_pa,p_im_est_pa,maf_sensor_kg_s,maf_est_kg_s,turbo_speed_meas_rad_s,turbo_speed_est_rad_s,turbo_speed_model_rad_s,dc_eta_vol,p_im_ve95_plain_pa,p_im_ve95_aug_pa,dc_ve95\n",
    );
    for (i, model_speed) in open.iter().enumerate().take(tr.t.len()) {
        let _ = writeln!(
            text,
            "{},{},{},{},{},{},{},{},{},{},{},{},{}",
            tr.t[i],
            tr.throttle_pct[i],
            tr.p_im_pa[i],
            bil.p_im_pa[i],
            tr.maf_kg_s[i],
            bil.maf_kg_s[i],
            tr.turbo_speed_rad_s[i],
            bil.turbo_speed_rad_s[i],
            model_speed,
            bil.dc[i],
            plain.p_im_pa[i],
            aug.p_im_pa[i],
            aug.dc[i]
        );
    }
    std::fs::write(&path, text).map_err(|source| TurboReproError::Write { file: path, source })
}

/// The model alone (no feedback) from the stationary point of the first input: turbo speed.
fn open_loop(
    model: &TurboModel,
    tr: &Transient,
    set: &LogSetting,
) -> Result<Vec<f64>, TurboReproError> {
    let step =
        fdd_estimators::models::turbo::discrete::TurboDiscrete::new(model.clone(), DT_S, DT_S)?
            .with_newton_tolerance(fdd_estimators::models::turbo::observer::OBSERVER_NEWTON_TOL)?;
    let mut x = model
        .stationary_point(&transient_input(tr, 0, set), None)?
        .state;
    let mut out = Vec::with_capacity(tr.t.len());
    for i in 0..tr.t.len() {
        if i > 0 {
            x = step.step(&x, &transient_input(tr, i - 1, set))?;
        }
        out.push(x[X_OMEGA_T]);
    }
    Ok(out)
}

/// The report as text.
pub fn render(r: &TurboReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Turbo air-path observer on the TSFS09 transients (ambient {:.0} Pa; R std p_im {:.0} Pa, air flow {:.2} g/s; Q turbo speed {:.0} rad/s; worst closed-loop radius {:.4})",
        r.ambient_pressure_pa,
        r.r_std[0],
        r.r_std[1] * 1e3,
        r.turbo_speed_q_rad_s,
        r.worst_closed_loop_radius
    );
    let _ = writeln!(s, "{:<44} {:>14} {:>14}", "figure", "tuning", "held-out");
    type Row = (&'static str, fn(&LogFigures) -> Option<f64>);
    let rows: [Row; 17] = [
        ("engine speed used (rpm)", |f| Some(f.engine_speed_rpm)),
        ("wastegate from the map (-)", |f| f.wastegate_frac),
        ("turbo speed RMS error (%)", |f| Some(f.turbo_speed_rms_pct)),
        ("  model alone (%)", |f| {
            Some(f.turbo_speed_rms_pct_open_loop)
        }),
        ("  nearest-node gains (%)", |f| {
            Some(f.nearest_turbo_speed_rms_pct)
        }),
        ("p_im sensor noise std (Pa)", |f| {
            Some(f.p_im_sensor_noise_pa)
        }),
        ("p_im estimate noise std (Pa)", |f| {
            Some(f.p_im_estimate_noise_pa)
        }),
        ("p_im noise ratio (%)", |f| Some(f.p_im_noise_ratio_pct)),
        ("  nearest-node gains (%)", |f| {
            Some(f.nearest_noise_ratio_pct)
        }),
        ("air flow estimate - sensor, RMS (%)", |f| {
            Some(f.maf_rms_pct)
        }),
        ("air flow noise ratio (%)", |f| Some(f.maf_noise_ratio_pct)),
        ("p_im lag (samples of 12.5 ms)", |f| f.p_im_lag_samples),
        ("  nearest-node gains (samples)", |f| f.nearest_lag_samples),
        ("VE -5 %: stationary p_im error plain (Pa)", |f| {
            Some(f.ve_error_plain_pa)
        }),
        ("VE -5 %: with dC_eta_vol (Pa)", |f| {
            Some(f.ve_error_augmented_pa)
        }),
        ("VE -5 %: error removed (%)", |f| {
            Some(f.ve_error_removed_pct)
        }),
        ("stationary segments", |f| Some(f.segments as f64)),
    ];
    for (name, f) in rows {
        let cell = |v: Option<f64>| v.map_or_else(|| "n/a".to_string(), |v| format!("{v:.3}"));
        let _ = writeln!(
            s,
            "{:<44} {:>14} {:>14}",
            name,
            cell(f(&r.tuning)),
            cell(f(&r.held_out))
        );
    }
    s
}
