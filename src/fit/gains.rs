//! `fdd fit turbo-gains`: designs the air-path observer's gain table for a parameter file and
//! writes it as a calibration file (`fdd_estimators::models::turbo::observer::file`), so that a
//! monitor loads gains instead of designing them (half a second of Riccati equations) when it
//! is built, as an ECU carries its calibration.
//!
//! Two sources of the state noise `Q` (the observer paper's method, the squared stationary model
//! error, [`fdd_estimators::models::turbo::observer::design`]):
//!
//! - `--log`: a fault-free driving log of an engine without an engine map (the LiU-ICE engine):
//!   the model's stationary error at the log's quasi-stationary samples, the samples
//!   `fdd fit turbo-ice` judges the model on ([`state_noise_from_log`]);
//! - `--map`: the TSFS09 engine map, exactly as `fdd reproduce turbo` takes it (the map's
//!   stationary errors, the turbo speed's from the airstep log's stationary start).
//!
//! The measurement noise `R` is the `[measurement_noise]` table of a parameter file (the
//! sensors' variance about a local mean, `fdd fit turbo-ice`), floored at each sensor's
//! accuracy ([`ACCURACY_FLOOR_STD`]): see there for why.
//!
//! The output is deterministic (one thread, a fixed order, numbers in round-trip form), and the
//! command refuses to write a table with a node whose closed loop is not stable.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use fdd_estimators::models::turbo::fit::ice::{quasi_stationary, IceOptions, LogSample};
use fdd_estimators::models::turbo::fit::FitError;
use fdd_estimators::models::turbo::observer::design::{
    design_gains_on_path, state_noise_at, state_noise_from_log, ActuatorPath, Conditions, Design,
    DesignError, DesignOptions, NoiseSample, Q_FLOOR_FRACTION, UNMEASURED_EXHAUST_TEMP_REL,
};
use fdd_estimators::models::turbo::observer::file::{
    GainFile, GainFileData, GainFileError, GainNodeRecord,
};
use fdd_estimators::models::turbo::observer::Sensor;
use fdd_estimators::models::turbo::{
    TurboError, TurboModel, TurboParams, N_STATES_AUGMENTED, STATE_NAMES, X_OMEGA_T,
};
use fdd_estimators::ParamError;
use thiserror::Error;

use super::{load_params, write_atomic, FitIoError};
use crate::reproduce::turbo as repro;

/// The sensors of every gain file this command writes, in column order: the LiU-ICE logs' and
/// the truth simulator's pressure after the intercooler, manifold pressure and air flow.
pub const SENSORS: [Sensor; 3] = [Sensor::PIc, Sensor::PIm, Sensor::Maf];
/// The monitor's sample time: the LiU-ICE logs' 20 Hz (s).
pub const SAMPLE_TIME_S: f64 = 0.05;

/// Floors of the sensors' noise standard deviations in `R` (sensor units: Pa, Pa, kg/s), in
/// [`SENSORS`] order: what a sensor's reading is worth to the observer, its accuracy, not only
/// its noise about a one-second mean.
///
/// The LiU-ICE boost pressure sensor logs with 21 Pa of noise; taken as `R`, the design trusts
/// it to 21 Pa, and the gains drive every state that moves `p_ic` (the compressor outlet's and
/// the intercooler's masses, `dC_eta_vol`, the manifold through the throttle) hard on every
/// mismatch between the model and the reading, which on the LiU-ICE drive is kilopascals
/// whenever the engine boosts (the model's boost side is not calibrated): with the measured
/// noise as `R` the MAF estimate left the reading by up to 89 % on the fault-free logs, the
/// `p_im` innovation reached 28 kPa RMS and `dC_eta_vol` -3.3 (with 2 % of the state scales as
/// `Q`, the turbo speed ran to its upper limit and the MAF estimate 47 times the reading off).
/// A pressure sensor's accuracy
/// over its range is of the order of 1 % of the reading (offset, gain and temperature errors of
/// automotive absolute-pressure sensors are specified at 1-2 % of their span), so both pressures
/// are floored at 1 kPa, 1 % of the ambient pressure; the air flow at 2 % of the LiU-ICE
/// calibration log's mean reading (2.98 g/s), 0.06 g/s (hot-film sensors are specified at
/// 2-3 % of the reading). The LiU-ICE design was also run with the pressure floors at 0.5 and
/// 2 kPa: the observer stays bounded on every LiU-ICE log with either.
pub const ACCURACY_FLOOR_STD: [f64; 3] = [1000.0, 1000.0, 6.0e-5];

/// LiU-ICE design grid, engine speed (rpm): the logs run 765-3500 rpm.
pub const LIU_SPEEDS_RPM: [f64; 7] = [750.0, 1000.0, 1500.0, 2000.0, 2500.0, 3000.0, 3600.0];
/// LiU-ICE design grid, manifold pressure (kPa): the logs' 20 kPa (closed throttle at speed)
/// to 87 kPa, and on to 100 kPa, the most the model reaches with the wastegate closed at
/// wide-open throttle (its boost side is VEP4's; a node above it is unreachable at every speed
/// and would only repeat the 100 kPa gains); nodes every 5 kPa where the city cycle spends its
/// time (20-40 kPa), every 10 kPa above. Outside the grid the lookup clamps to its edge.
pub const LIU_PRESSURES_KPA: [f64; 11] = [
    20.0, 25.0, 30.0, 35.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0, 100.0,
];
/// A wastegate reading above this counts as "not closed" when the part-load opening of the
/// actuator path is taken from a log (the LiU-ICE column is 0 or 0.61-0.65).
pub const WASTEGATE_OPEN_THRESHOLD: f64 = 0.3;

/// Where `Q` comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NoiseSource {
    /// A fault-free LiU-ICE log (MCAP).
    Log(PathBuf),
    /// A TSFS09 data directory (engine map and the airstep transient).
    Map(PathBuf),
}

/// The command's arguments.
#[derive(Debug, Clone)]
pub struct FitGainsArgs {
    /// The model's parameter file.
    pub params: PathBuf,
    /// The parameter file whose `[measurement_noise]` gives `R` (often `params` itself).
    pub measurement_noise: PathBuf,
    /// Where `Q` comes from.
    pub source: NoiseSource,
    /// The output gain file.
    pub out: PathBuf,
}

/// What can go wrong.
#[derive(Debug, Error)]
pub enum FitGainsError {
    /// Reading a parameter file, a log or the map.
    #[error(transparent)]
    Io(#[from] FitIoError),
    /// Reading the TSFS09 transient.
    #[error(transparent)]
    Repro(#[from] repro::TurboReproError),
    /// The `[measurement_noise]` table is missing or incomplete.
    #[error("{}: [measurement_noise] {key}: {problem}", file.display())]
    Noise {
        /// The file.
        file: PathBuf,
        /// The key.
        key: &'static str,
        /// What is wrong.
        problem: String,
    },
    /// The design.
    #[error(transparent)]
    Design(#[from] DesignError),
    /// The model.
    #[error("turbo model: {0}")]
    Model(#[from] TurboError),
    /// A parameter.
    #[error("turbo model: {0}")]
    Param(#[from] ParamError),
    /// The map check.
    #[error("engine map check: {0}")]
    Fit(#[from] FitError),
    /// No state-noise sample.
    #[error("{}: no quasi-stationary sample with a stationary point to take the state noise from", file.display())]
    NoNoise {
        /// The log.
        file: PathBuf,
    },
    /// A node's closed loop is not stable: the table is not written.
    #[error("the closed loop at {speed_rpm:.0} rpm, {pressure_kpa:.0} kPa has spectral radius {radius} (not below 1); no gain file written")]
    Unstable {
        /// Node speed (rpm).
        speed_rpm: f64,
        /// Node pressure (kPa).
        pressure_kpa: f64,
        /// The radius.
        radius: f64,
    },
    /// The output would overwrite an input.
    #[error("{}: refusing to write the gain file over an input", file.display())]
    OutputIsInput {
        /// The output.
        file: PathBuf,
    },
    /// The table does not make a valid file (cannot happen for a design that succeeded).
    #[error(transparent)]
    File(#[from] GainFileError),
    /// A gain file cannot be read.
    #[error("cannot read {}: {source}", file.display())]
    Read {
        /// The file.
        file: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A gain file is not valid TOML or has an unknown or missing key.
    #[error("{}: {message}", file.display())]
    Parse {
        /// The file.
        file: PathBuf,
        /// The parser's message (it names the line and the key).
        message: String,
    },
}

/// The `[measurement_noise]` variances of a parameter file, in [`SENSORS`] order.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredNoise {
    /// Variances (Pa^2, Pa^2, kg^2/s^2).
    pub variance: [f64; 3],
}

/// Reads the `[measurement_noise]` table `fdd fit turbo-ice` writes.
pub fn load_measurement_noise(path: &Path) -> Result<MeasuredNoise, FitGainsError> {
    let text = std::fs::read_to_string(path).map_err(|source| FitGainsError::Read {
        file: path.to_path_buf(),
        source,
    })?;
    let table: toml::Table = toml::from_str(&text).map_err(|e| FitGainsError::Parse {
        file: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let noise = table
        .get("measurement_noise")
        .and_then(|v| v.as_table())
        .ok_or_else(|| FitGainsError::Noise {
            file: path.to_path_buf(),
            key: "(the table)",
            problem: "no [measurement_noise] table (fdd fit turbo-ice writes one)".into(),
        })?;
    const KEYS: [&str; 3] = [
        "p_ic_variance_pa2",
        "p_im_variance_pa2",
        "w_af_variance_kg2_per_s2",
    ];
    let mut variance = [0.0; 3];
    for (v, key) in variance.iter_mut().zip(KEYS) {
        let x = noise
            .get(key)
            .and_then(|x| x.as_float().or_else(|| x.as_integer().map(|i| i as f64)))
            .ok_or_else(|| FitGainsError::Noise {
                file: path.to_path_buf(),
                key,
                problem: "missing or not a number".into(),
            })?;
        if !(x.is_finite() && x > 0.0) {
            return Err(FitGainsError::Noise {
                file: path.to_path_buf(),
                key,
                problem: format!("{x} is not a positive variance"),
            });
        }
        *v = x;
    }
    Ok(MeasuredNoise { variance })
}

/// `R`: each measured variance floored at the sensor's accuracy ([`ACCURACY_FLOOR_STD`]).
pub fn floored_r(noise: &MeasuredNoise) -> [f64; 3] {
    std::array::from_fn(|i| noise.variance[i].max(ACCURACY_FLOOR_STD[i].powi(2)))
}

/// What the command computed.
#[derive(Debug, Clone)]
pub struct FitGainsRun {
    /// The design.
    pub design: Design<3>,
    /// The file as loaded back.
    pub file: GainFile<3>,
    /// The file's text as written.
    pub file_text: String,
}

/// Everything the header says about the noise.
struct NoiseStory {
    lines: Vec<String>,
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    s / n.max(1) as f64
}

/// The median of `v` (0 if empty).
fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// The LiU-ICE design from a log: noise samples, conditions, actuator path and story.
fn from_log(
    model: &TurboModel,
    log: &Path,
) -> Result<(Vec<NoiseSample>, Conditions, ActuatorPath, NoiseStory), FitGainsError> {
    let samples: Vec<LogSample> = super::ice::read_log(log)?;
    let opts = IceOptions::liu_ice();
    // No turbo speed is logged and the LiU-ICE set's turbo side is VEP4's, undetermined by the
    // log: the turbo speed's noise is the floor (see the header text below for why).
    let turbo_floor = Q_FLOOR_FRACTION * model.state_scales()[X_OMEGA_T];
    let noise = state_noise_from_log(model, &samples, &opts, turbo_floor);
    if noise.is_empty() {
        return Err(FitGainsError::NoNoise {
            file: log.to_path_buf(),
        });
    }
    let n_qs = quasi_stationary(&samples, &opts)
        .iter()
        .filter(|m| **m)
        .count();
    let conditions = Conditions {
        ambient_pressure_pa: mean(samples.iter().map(|s| s.ambient_pressure_pa)),
        ambient_temperature_k: mean(samples.iter().map(|s| s.ambient_temperature_k)),
        lambda: opts.lambda,
    };
    let open = median(
        samples
            .iter()
            .map(|s| s.wastegate)
            .filter(|w| *w > WASTEGATE_OPEN_THRESHOLD)
            .collect(),
    );
    // A log whose wastegate never opens past the threshold says nothing about its part-load
    // opening: the default path (fully open) then.
    let path = ActuatorPath {
        wastegate_open: if open > 0.0 { open.min(1.0) } else { 1.0 },
    };
    let log_name = shown(log);
    let lines = vec![
        format!("Q: the model's stationary error at the {} quasi-stationary samples of the calibration", noise.len()),
        format!("log {log_name} ({n_qs} quasi-stationary of {} rows, the samples `fdd fit turbo-ice`", samples.len()),
        "judges the model on; no other log is read): per sample the model's stationary point at the".into(),
        "sample's inputs against the measured p_ic, T_ic, p_im and air flow; a volume's mass error is".into(),
        "its pressure error through M = pV/(RT), a node takes the mean of the 4 nearest samples in".into(),
        "(speed, p_im). Substitutes for what the log does not measure: air filter and exhaust masses".into(),
        "from the relative flow error through their restrictions (dp = 2 e_W dp_restriction); the".into(),
        "compressor outlet the intercooler's errors; T_af, T_c and T_im the T_ic error;".into(),
        format!("exhaust temperatures {:.0} % of the model's; dC_eta_vol e_W times the efficiency factor.", 100.0 * UNMEASURED_EXHAUST_TEMP_REL),
        format!("The turbo speed's entry is the floor ({turbo_floor:.0} rad/s): no turbo speed is logged, the model's"),
        "turbo side is VEP4's (the log does not determine it), and at idle and low load the model's".into(),
        "turbo speed sits on its lower limit, where its linearization decouples it from every sensor:".into(),
        "the gains there cannot know how the turbo speed acts once the estimate leaves the limit.".into(),
        "With the turbo speed's noise at 3500 rad/s (about the TSFS09 figure, 50 % of the model's".into(),
        "part-load speed) and the pressure floors of R at 0.5 kPa the observer diverged on three".into(),
        "LiU-ICE logs (the turbo speed driven to its upper limit to explain boost the model cannot".into(),
        "make); at the floor it follows the model, and it stays bounded with pressure floors from".into(),
        "0.5 to 2 kPa.".into(),
        format!("Every entry floored at {} % of the state's scale.", 100.0 * Q_FLOOR_FRACTION),
        format!("Operating points: ambient {:.0} Pa, {:.2} K (the log's means), lambda 1; actuator path with", conditions.ambient_pressure_pa, conditions.ambient_temperature_k),
        format!("the wastegate at {open:.4} while the throttle opens (the log's median position where it is not"),
        format!("closed, above {WASTEGATE_OPEN_THRESHOLD}), then closing at wide-open throttle."),
    ];
    Ok((noise, conditions, path, NoiseStory { lines }))
}

fn from_map(
    model: &TurboModel,
    params: &TurboParams,
    dir: &Path,
) -> Result<(Vec<NoiseSample>, Conditions, ActuatorPath, NoiseStory), FitGainsError> {
    let repro::MapNoise {
        ambient_pressure_pa: ambient,
        noise,
        tuning_setting,
        turbo_speed_error_rad_s: q_speed,
        ..
    } = repro::map_noise(model, params, dir)?;
    let speed = tuning_setting.engine_speed_rad_s;
    let conditions = Conditions {
        ambient_pressure_pa: ambient,
        ambient_temperature_k: repro::AMBIENT_TEMPERATURE_K,
        lambda: 1.0,
    };
    let d = shown(dir);
    let lines = vec![
        format!("Q: as `fdd reproduce turbo` takes it: the model's stationary error at the {} points of", noise.len()),
        format!("the engine map {d}/engine_map.csv (`state_noise_from_map`: a volume's mass error"),
        "from its pressure error, the compressor outlet the intercooler's errors, dC_eta_vol the".into(),
        "relative air-flow error times the efficiency factor; a node takes the mean of the 4 nearest".into(),
        format!("map points); the turbo speed's entry {q_speed:.0} rad/s, the RMS of the model's stationary turbo"),
        format!("speed against the measured one over the stationary segments of {} ({:.0} rpm read", repro::TUNING_LOG, speed * 60.0 / std::f64::consts::TAU),
        format!("off the map). Every entry floored at {} % of the state's scale.", 100.0 * Q_FLOOR_FRACTION),
        format!("Operating points: ambient {ambient:.0} Pa (the map's air filter fit), {:.0} K, lambda 1;", repro::AMBIENT_TEMPERATURE_K),
        "actuator path with the wastegate fully open while the throttle opens, then closing.".into(),
    ];
    Ok((
        noise,
        conditions,
        ActuatorPath::default(),
        NoiseStory { lines },
    ))
}

/// A file name for the header (the path as given, `/` separated).
fn shown(p: &Path) -> String {
    p.to_string_lossy().replace('\\', "/")
}

/// Runs the design and writes the gain file.
pub fn run(args: &FitGainsArgs) -> Result<FitGainsRun, FitGainsError> {
    let source_path = match &args.source {
        NoiseSource::Log(p) | NoiseSource::Map(p) => p.clone(),
    };
    if let Ok(out) = args.out.canonicalize() {
        let inputs = [&args.params, &args.measurement_noise, &source_path];
        if inputs
            .iter()
            .any(|i| i.canonicalize().is_ok_and(|i| i == out))
        {
            return Err(FitGainsError::OutputIsInput {
                file: args.out.clone(),
            });
        }
    }
    let params = load_params(&args.params)?;
    let model = TurboModel::new(params.clone())?;
    let measured = load_measurement_noise(&args.measurement_noise)?;
    let r = floored_r(&measured);
    let (noise, conditions, path, story, speeds_rpm, pressures_kpa) = match &args.source {
        NoiseSource::Log(log) => {
            let (n, c, p, s) = from_log(&model, log)?;
            (
                n,
                c,
                p,
                s,
                LIU_SPEEDS_RPM.to_vec(),
                LIU_PRESSURES_KPA.to_vec(),
            )
        }
        NoiseSource::Map(dir) => {
            let (n, c, p, s) = from_map(&model, &params, dir)?;
            (
                n,
                c,
                p,
                s,
                repro::GRID_SPEEDS_RPM.to_vec(),
                repro::GRID_PRESSURES_KPA.to_vec(),
            )
        }
    };
    let opts = DesignOptions {
        dt_s: SAMPLE_TIME_S,
        sensors: SENSORS,
        r,
        speeds_rad_s: speeds_rpm
            .iter()
            .map(|n| n * std::f64::consts::TAU / 60.0)
            .collect(),
        pressures_pa: pressures_kpa.iter().map(|p| p * 1e3).collect(),
        conditions,
    };
    let design = design_gains_on_path(&model, &opts, &noise, &path)?;
    if let Some(bad) = design.nodes.iter().find(|n| !(n.closed_loop_radius < 1.0)) {
        return Err(FitGainsError::Unstable {
            speed_rpm: bad.speed_rad_s * 60.0 / std::f64::consts::TAU,
            pressure_kpa: bad.pressure_pa / 1e3,
            radius: bad.closed_loop_radius,
        });
    }
    let file = GainFile {
        sensors: SENSORS,
        sample_time_s: SAMPLE_TIME_S,
        measurement_variance: r,
        ambient_pressure_pa: conditions.ambient_pressure_pa,
        ambient_temperature_k: conditions.ambient_temperature_k,
        lambda: conditions.lambda,
        table: design.table.clone(),
        nodes: design
            .nodes
            .iter()
            .map(|n| GainNodeRecord {
                speed_rad_s: n.speed_rad_s,
                pressure_pa: n.pressure_pa,
                reachable: n.point.is_some(),
                throttle_pct: n.design_point.input.throttle_pct,
                wastegate_frac: n.design_point.input.wastegate_frac,
                closed_loop_radius: n.closed_loop_radius,
            })
            .collect(),
    };
    let header = header(args, &model, &measured, &r, &noise, &story, &design);
    let file_text = format!("{header}\n{}", file.render());
    // What is written must load back to the same table.
    let data: GainFileData = toml::from_str(&file_text).map_err(|e| FitGainsError::Parse {
        file: args.out.clone(),
        message: e.to_string(),
    })?;
    let loaded = GainFile::<3>::from_data(&shown(&args.out), &data)?;
    write_atomic(&args.out, &file_text)?;
    Ok(FitGainsRun {
        design,
        file: loaded,
        file_text,
    })
}

/// The command line that reproduces the file.
fn command_line(args: &FitGainsArgs) -> String {
    let source = match &args.source {
        NoiseSource::Log(p) => format!("--log {}", shown(p)),
        NoiseSource::Map(p) => format!("--map {}", shown(p)),
    };
    format!(
        "fdd fit turbo-gains --params {} --measurement-noise {} \\\n#       {source} -o {}",
        shown(&args.params),
        shown(&args.measurement_noise),
        shown(&args.out)
    )
}

fn header(
    args: &FitGainsArgs,
    model: &TurboModel,
    measured: &MeasuredNoise,
    r: &[f64; 3],
    noise: &[NoiseSample],
    story: &NoiseStory,
    design: &Design<3>,
) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Gain table of the air-path observer (fdd_estimators::models::turbo::observer) for the model"
    );
    let _ = writeln!(
        s,
        "# {}: stationary Kalman gains (14 states x the sensors p_ic, p_im, maf) of the model",
        shown(&args.params)
    );
    let _ = writeln!(
        s,
        "# linearized and discretized at {SAMPLE_TIME_S} s at each node of a grid of engine speed x manifold"
    );
    let _ = writeln!(
        s,
        "# pressure, looked up bilinearly at the engine speed and the predicted p_im. Generated by"
    );
    let _ = writeln!(
        s,
        "# `fdd fit turbo-gains` (do not edit; FDD_BLESS=1 cargo test --release --test fit_turbo_gains"
    );
    let _ = writeln!(s, "# regenerates it):\n#\n#   {}\n#", command_line(args));
    for l in &story.lines {
        let _ = writeln!(s, "# {l}");
    }
    let _ = writeln!(s, "#");
    let _ = writeln!(
        s,
        "# R: the [measurement_noise] of {} (each sensor's variance about a 1 s local mean at",
        shown(&args.measurement_noise)
    );
    let _ = writeln!(
        s,
        "# quasi-stationary samples of the LiU-ICE calibration log), floored at the sensor's accuracy"
    );
    let _ = writeln!(
        s,
        "# (src/fit/gains.rs, ACCURACY_FLOOR_STD: a reading is not worth more to the observer than its"
    );
    let _ = writeln!(
        s,
        "# accuracy; with the 21 Pa p_ic noise as R the observer diverged on the LiU-ICE drive):"
    );
    if let NoiseSource::Map(_) = args.source {
        for l in [
            "# The LiU-ICE engine's noise for the TSFS09 model: the gains are for the simulated logs of",
            "# the truth simulator (fdd_fixtures::turbo_*), whose sensors carry the noise measured on the",
            "# LiU-ICE logs; the TSFS09 transients log no boost pressure to measure it on.",
        ] {
            let _ = writeln!(s, "{l}");
        }
    }
    let units = [("Pa", 1.0), ("Pa", 1.0), ("g/s", 1e3)];
    for (i, sensor) in SENSORS.iter().enumerate() {
        let (u, k) = units[i];
        let _ = writeln!(
            s,
            "#   {:<4} measured std {:>9.4} {u:<3}  floor {:>9.4} {u:<3}  R std {:>9.4} {u}",
            sensor.name(),
            measured.variance[i].sqrt() * k,
            ACCURACY_FLOOR_STD[i] * k,
            r[i].sqrt() * k
        );
    }
    let _ = writeln!(
        s,
        "# Discretized as Q dt and R / dt (the paper's densities per second)."
    );
    let _ = writeln!(s, "#");
    let _ = writeln!(
        s,
        "# Q per state over the nodes (std as % of the state's scale: min / median / max):"
    );
    let scales = model.state_scales();
    let per_node: Vec<[f64; N_STATES_AUGMENTED]> = design
        .nodes
        .iter()
        .filter_map(|n| state_noise_at(noise, n.speed_rad_s, n.design_point.p_im_pa))
        .collect();
    for (i, name) in STATE_NAMES.iter().enumerate() {
        let v: Vec<f64> = per_node
            .iter()
            .map(|q| 100.0 * q[i].sqrt() / scales[i])
            .collect();
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let _ = writeln!(
            s,
            "#   {name:<16} {lo:>8.3} {:>8.3} {hi:>8.3}",
            median(v.clone())
        );
    }
    let _ = writeln!(s, "#");
    let _ = writeln!(
        s,
        "# Nodes: the operating point each gain was designed at (an unreachable node, marked *, takes"
    );
    let _ = writeln!(
        s,
        "# the nearest reachable one's at its speed) and the closed loop's spectral radius:"
    );
    let _ = writeln!(
        s,
        "#   {:>6} {:>7} | {:>8} {:>6} {:>8} {:>8} {:>8} | {:>8}",
        "rpm", "kPa", "throttle", "wg", "p_im kPa", "p_ic kPa", "omega_t", "radius"
    );
    for n in &design.nodes {
        let op = &n.design_point;
        let sig = model.signals(&op.state, &op.input);
        let _ = writeln!(
            s,
            "#   {:>6.0} {:>6.0}{} | {:>8.3} {:>6.3} {:>8.2} {:>8.2} {:>8.0} | {:>8.5}",
            n.speed_rad_s * 60.0 / std::f64::consts::TAU,
            n.pressure_pa / 1e3,
            if n.point.is_some() { " " } else { "*" },
            op.input.throttle_pct,
            op.input.wastegate_frac,
            op.p_im_pa / 1e3,
            sig.p_ic_pa / 1e3,
            op.state[X_OMEGA_T],
            n.closed_loop_radius
        );
    }
    let worst = design
        .nodes
        .iter()
        .map(|n| n.closed_loop_radius)
        .fold(0.0, f64::max);
    let _ = writeln!(
        s,
        "# Largest spectral radius: {worst:.5} (all below 1: every node's closed loop is stable)."
    );
    s
}

/// Loads a gain file written by this command, checking it against the observer's sensors and
/// sample time; every error names the file and the key.
pub fn load_gain_file(path: &Path) -> Result<GainFile<3>, FitGainsError> {
    let text = std::fs::read_to_string(path).map_err(|source| FitGainsError::Read {
        file: path.to_path_buf(),
        source,
    })?;
    let data: GainFileData = toml::from_str(&text).map_err(|e| FitGainsError::Parse {
        file: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let name = shown(path);
    let file = GainFile::<3>::from_data(&name, &data)?;
    file.expect(&name, &SENSORS, SAMPLE_TIME_S)?;
    Ok(file)
}
