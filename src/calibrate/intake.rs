//! `fdd calibrate` for the intake monitor: from fault-free logs of one engine, its sensors'
//! noise, the range its learned corrections need, and every residual test's threshold for a
//! stated false-alarm rate.
//!
//! Method (a client of the runtime, like the throttle's calibration in the
//! [parent module](super)):
//!
//! 1. **Noise.** A first pass replays every log with the thresholds out of reach. The raw MAP
//!    and MAF samples give the noise levels from the monitor's noise-test difference over four
//!    consecutive segments (`fdd_monitor::intake::noise_difference`, `(y0 - y1 - y2 + y3) /
//!    2`), kept only while the throttle has been steady (the monitor's own rule: for
//!    `noise_settle_segments`, no segment faster than `noise_max_throttle_rate_deg_s` or changing
//!    its rate by more than `noise_max_throttle_rate_change_deg_s`): a live reading's change
//!    over four segments is nearly linear there, and the difference also cancels a component
//!    alternating from segment to segment (aliased intake pulsation), so what is left is noise
//!    of variance `R` (relative to the reading for the MAF). A robust scale (1.4826 times the
//!    median absolute deviation) ignores the transients that slip through. The MAF's absolute `R`
//!    (`maf_noise_kg_s`) is its relative noise at a 20 g/s mid-load flow, as in the default.
//! 2. **Model error.** The monitor learns the volumetric-efficiency / MAF ratio and the
//!    throttle discharge ratio online (`maf_correction`, `throttle_correction`), each within
//!    `1 +- adapt_limit`. The same pass reads them unbounded; `adapt_limit` becomes 1.25 times
//!    the largest deviation from 1 seen after the first `adapt_time_s` of each log (or the
//!    starting configuration's, whichever is larger), so that a plant further off the model
//!    than the default allows is corrected, not alarmed on.
//! 3. **Thresholds.** A second pass with those values (thresholds still out of reach) cuts each
//!    test statistic into blocks; the generalized extreme-value fit of the block maxima and
//!    its checks are the throttle's (`fit_threshold`). The two NIS window tests share
//!    `nis_threshold` and the two noise tests `noise_threshold`: each pair is one statistic, the
//!    larger of the two in each block.
//! 4. **Refusals** as for the throttle: a log with a fault active, too little data, a fit that
//!    does not hold, data above their own threshold.

use std::path::{Path, PathBuf};

use fdd_diagnostics::Verdict;
use fdd_monitor::config::{IntakeConfig, DEFAULT_INTAKE_TOML};
use fdd_monitor::intake::noise_difference;
use fdd_monitor::monitor::Output;
use fdd_monitor::runtime::config::TruthConfig;
use fdd_monitor::runtime::Runtime;

use super::{
    block_max, check_extrapolation, fit_threshold, monitor_text, refuse_fault, replay_input,
    runtime_naming, runtime_with_only, with_monitor_keys, CalibrateError, CalibrateOptions, Only,
    TestCalibration,
};
use crate::replay::{ReplayObserver, RuntimeConfig};

/// The thresholds calibrated: (`[monitor]` key, name in the report, the test outputs whose
/// statistics it bounds).
const TESTS: [(&str, &str, &[&str]); 5] = [
    (
        "pressure_cusum_threshold",
        "intake_pressure_consistency",
        &["intake_pressure_consistency"],
    ),
    (
        "flow_cusum_threshold",
        "intake_flow_consistency",
        &["intake_flow_consistency"],
    ),
    (
        "throttle_cusum_threshold",
        "intake_throttle_model",
        &["intake_throttle_model"],
    ),
    (
        "nis_threshold",
        "intake_nis",
        &["intake_centralized_nis", "intake_federated_nis"],
    ),
    (
        "noise_threshold",
        "intake_noise",
        &["intake_map_noise", "intake_maf_noise"],
    ),
];

/// Thresholds of the calibration passes: out of reach of any fault-free statistic, and small
/// enough that the CUSUMs' mean run length between false alarms stays a finite number.
const UNREACHABLE_CUSUM: f64 = 300.0;
const UNREACHABLE_NIS: f64 = 1e12;
/// Correction range of the first pass, wide enough to see what the plant asks (-).
const WIDE_ADAPT_LIMIT: f64 = 0.3;
/// The learned noise level's bounds in the passes (the noise tests then follow whatever the
/// sensors do).
const WIDE_NOISE_LEARN_LIMIT: f64 = 100.0;
/// Flow at which the MAF's absolute `R` is its relative noise (kg/s), as in the default.
const MAF_R_FLOW_KG_S: f64 = 0.02;
/// Margin on the largest learned correction seen (-).
const ADAPT_MARGIN: f64 = 1.25;
/// Noise differences kept per sensor for the noise estimate (bounds the memory on long
/// logs).
const MAX_NOISE_SAMPLES: usize = 4_000_000;
/// Fewest steady noise differences per sensor for a noise estimate.
const MIN_NOISE_SAMPLES: usize = 1_000;

/// The result: the levels and thresholds, and the configuration texts to write.
#[derive(Debug, Clone)]
pub struct IntakeCalibration {
    pub logs: Vec<PathBuf>,
    pub hours: f64,
    /// MAP noise std (Pa) and MAF relative noise (-), and how many steady noise differences
    /// each came from.
    pub map_noise_pa: f64,
    pub maf_noise_rel: f64,
    pub noise_samples: [usize; 2],
    /// Largest deviation from 1 of the learned MAF and throttle corrections, and the
    /// `adapt_limit` set.
    pub correction_dev: [f64; 2],
    pub adapt_limit: f64,
    pub tests: Vec<TestCalibration>,
    /// `intake.toml` and `fdd.toml` texts.
    pub intake_toml: String,
    pub runtime_toml: String,
}

/// Noise differences (four segments, see the module docs) of one sensor's readings.
#[derive(Default)]
struct NoiseDiff {
    last: [f64; 3],
    n: u8,
    values: Vec<f64>,
}

impl NoiseDiff {
    fn reset(&mut self) {
        self.n = 0;
    }

    /// Takes reading `v`; keeps its noise difference (divided by the mean of the two middle
    /// readings when `relative`) when `keep`.
    fn push(&mut self, v: f64, keep: bool, relative: bool) {
        if !v.is_finite() {
            self.n = 0;
            return;
        }
        if self.n >= 3 && keep && self.values.len() < MAX_NOISE_SAMPLES {
            let d = noise_difference(v, self.last[2], self.last[1], self.last[0]);
            let d = if relative {
                let mid = 0.5 * (self.last[2] + self.last[1]);
                if mid > 0.0 {
                    d / mid
                } else {
                    f64::NAN
                }
            } else {
                d
            };
            if d.is_finite() {
                self.values.push(d);
            }
        }
        self.last = [self.last[1], self.last[2], v];
        self.n = (self.n + 1).min(3);
    }

    /// The noise standard deviation: 1.4826 MAD (the difference has the noise's variance);
    /// NaN with too few values.
    fn std(&self) -> f64 {
        if self.values.len() < MIN_NOISE_SAMPLES {
            return f64::NAN;
        }
        let mut v = self.values.clone();
        let mid = v.len() / 2;
        let med = *v.select_nth_unstable_by(mid, f64::total_cmp).1;
        let mut dev: Vec<f64> = v.iter().map(|x| (x - med).abs()).collect();
        let mad = *dev.select_nth_unstable_by(mid, f64::total_cmp).1;
        1.4826 * mad
    }
}

/// What one pass gathers.
struct Collector {
    block_ns: u64,
    /// Runtime signal names: MAP, MAF, throttle.
    signals: [String; 3],
    max_throttle_rate: f64,
    max_throttle_rate_change: f64,
    settle: u32,
    adapt_time_ns: u64,
    maxima: [Vec<(f64, usize, f64)>; TESTS.len()],
    current: [Option<(u64, f64)>; TESTS.len()],
    log_index: usize,
    map: NoiseDiff,
    maf: NoiseDiff,
    last_throttle: Option<(u64, f64)>,
    last_throttle_rate: Option<f64>,
    steady_run: u32,
    correction_dev: [f64; 2],
    fault: Option<(String, f64)>,
    first_ns: Option<u64>,
    last_ns: u64,
    total_ns: u64,
}

impl Collector {
    fn new(cfg: &IntakeConfig, block_s: f64) -> Self {
        let m = &cfg.monitor;
        Self {
            block_ns: (block_s * 1e9) as u64,
            signals: [
                m.map_signal.clone(),
                m.maf_signal.clone(),
                m.throttle_signal.clone(),
            ],
            max_throttle_rate: m.noise_max_throttle_rate_deg_s,
            max_throttle_rate_change: m.noise_max_throttle_rate_change_deg_s,
            settle: m.noise_settle_segments,
            adapt_time_ns: (m.adapt_time_s * 1e9) as u64,
            maxima: Default::default(),
            current: [None; TESTS.len()],
            log_index: 0,
            map: NoiseDiff::default(),
            maf: NoiseDiff::default(),
            last_throttle: None,
            last_throttle_rate: None,
            steady_run: 0,
            correction_dev: [0.0; 2],
            fault: None,
            first_ns: None,
            last_ns: 0,
            total_ns: 0,
        }
    }

    fn steady(&self) -> bool {
        self.steady_run > self.settle
    }
}

impl ReplayObserver for Collector {
    fn begin_log(&mut self, _rt: &Runtime, _truths: &[TruthConfig]) {
        self.current = [None; TESTS.len()];
        self.map.reset();
        self.maf.reset();
        self.last_throttle = None;
        self.last_throttle_rate = None;
        self.steady_run = 0;
        self.first_ns = None;
    }

    fn sample(&mut self, t_ns: u64, signal: &str, value: f64) {
        if signal == self.signals[2] {
            if let Some((t0, v0)) = self.last_throttle {
                let dt = t_ns.saturating_sub(t0) as f64 * 1e-9;
                let rate = if dt > 0.0 {
                    (value - v0) / dt
                } else {
                    f64::INFINITY
                };
                let change = self.last_throttle_rate.map_or(0.0, |r| (rate - r).abs());
                self.steady_run = if rate.abs() <= self.max_throttle_rate
                    && change <= self.max_throttle_rate_change
                {
                    self.steady_run.saturating_add(1)
                } else {
                    0
                };
                self.last_throttle_rate = rate.is_finite().then_some(rate);
            }
            self.last_throttle = Some((t_ns, value));
        } else if signal == self.signals[0] {
            let keep = self.steady();
            self.map.push(value, keep, false);
        } else if signal == self.signals[1] {
            let keep = self.steady();
            self.maf.push(value, keep, true);
        }
    }

    fn output(&mut self, t_ns: u64, monitor: &str, output: &Output<'_>) {
        if monitor != "intake" {
            return;
        }
        let first = *self.first_ns.get_or_insert(t_ns);
        self.last_ns = self.last_ns.max(t_ns);
        match *output {
            Output::Test { test, result } if result.verdict != Verdict::NotTested => {
                let Some(i) = TESTS.iter().position(|(_, _, t)| t.contains(&test)) else {
                    return;
                };
                block_max(
                    &mut self.current[i],
                    &mut self.maxima[i],
                    (t_ns, self.block_ns, self.log_index),
                    result.value,
                );
            }
            Output::Estimate { name, value, .. } if t_ns >= first + self.adapt_time_ns => {
                let k = match name {
                    "maf_correction" => 0,
                    "throttle_correction" => 1,
                    _ => return,
                };
                if value.is_finite() {
                    self.correction_dev[k] = self.correction_dev[k].max((value - 1.0).abs());
                }
            }
            _ => {}
        }
    }

    fn truth(&mut self, t_ns: u64, _index: usize, fault: &str, active: bool, _o: Option<bool>) {
        if active && self.fault.is_none() {
            self.fault = Some((fault.to_string(), t_ns as f64 * 1e-9));
        }
    }

    fn end_log(&mut self) {
        // The last, partial block is dropped.
        self.current = [None; TESTS.len()];
        if let Some(a) = self.first_ns {
            self.total_ns += self.last_ns.saturating_sub(a);
        }
        self.last_ns = 0;
    }
}

/// Runs every log through the runtime of `cfg`, refusing one with a fault active.
fn pass(
    logs: &[PathBuf],
    cfg: &RuntimeConfig,
    intake: &IntakeConfig,
    block_s: f64,
) -> Result<Collector, CalibrateError> {
    let mut c = Collector::new(intake, block_s);
    for (i, file) in logs.iter().enumerate() {
        c.log_index = i;
        c.fault = None;
        replay_input(file, cfg, &mut c)?;
        refuse_fault(file, c.fault.take())?;
    }
    Ok(c)
}

/// A runtime configuration whose intake monitor alone reads `text` (written to `dir`), and
/// that text parsed.
fn runtime_with(
    base: &RuntimeConfig,
    dir: &Path,
    text: &str,
) -> Result<(RuntimeConfig, IntakeConfig), CalibrateError> {
    let cfg = runtime_with_only(base, dir, text, Only::Intake)?;
    let path = dir.join("intake.toml");
    let parsed = IntakeConfig::parse(text, &path.display().to_string())?;
    Ok((cfg, parsed))
}

/// Calibrates the intake monitor of `base` on the fault-free logs `logs` (see the
/// [module documentation](self)).
pub fn calibrate(
    logs: Vec<PathBuf>,
    base: &RuntimeConfig,
    opts: &CalibrateOptions,
) -> Result<IntakeCalibration, CalibrateError> {
    let (text, origin) = monitor_text(
        base.monitors.intake_config.as_deref(),
        DEFAULT_INTAKE_TOML,
        "config/intake.toml",
    )?;
    let start = IntakeConfig::parse(&text, &origin)?;
    let work = tempfile::tempdir().map_err(crate::evaluate::EvaluateError::Temp)?;
    let unreachable = [
        ("pressure_cusum_threshold", UNREACHABLE_CUSUM),
        ("flow_cusum_threshold", UNREACHABLE_CUSUM),
        ("throttle_cusum_threshold", UNREACHABLE_CUSUM),
        ("nis_threshold", UNREACHABLE_NIS),
        ("noise_threshold", UNREACHABLE_CUSUM),
        ("noise_learn_limit", WIDE_NOISE_LEARN_LIMIT),
    ];

    // Pass 1: noise and corrections.
    let mut keys: Vec<(&str, f64)> = unreachable.to_vec();
    keys.push(("adapt_limit", WIDE_ADAPT_LIMIT));
    let pass1 = with_monitor_keys(&text, &origin, &keys)?;
    let (cfg, parsed) = runtime_with(base, work.path(), &pass1)?;
    let c = pass(&logs, &cfg, &parsed, opts.block_s)?;
    let map_noise_pa = c.map.std();
    let maf_noise_rel = c.maf.std();
    if !(map_noise_pa > 0.0 && maf_noise_rel > 0.0) {
        return Err(CalibrateError::NoData("intake_map_noise"));
    }
    let correction_dev = c.correction_dev;
    let adapt_limit = (ADAPT_MARGIN * correction_dev[0].max(correction_dev[1]))
        .max(start.monitor.adapt_limit)
        .min(WIDE_ADAPT_LIMIT);
    let noise_samples = [c.map.values.len(), c.maf.values.len()];
    drop(c);

    // Pass 2: the statistics at those values.
    let values = [
        ("map_noise_pa", map_noise_pa),
        ("maf_noise_rel", maf_noise_rel),
        ("maf_noise_kg_s", maf_noise_rel * MAF_R_FLOW_KG_S),
        ("adapt_limit", adapt_limit),
    ];
    let mut keys: Vec<(&str, f64)> = unreachable.to_vec();
    keys.extend(values);
    let pass2 = with_monitor_keys(&text, &origin, &keys)?;
    let (cfg, parsed) = runtime_with(base, work.path(), &pass2)?;
    let c = pass(&logs, &cfg, &parsed, opts.block_s)?;
    let hours = c.total_ns as f64 * 1e-9 / 3600.0;
    check_extrapolation(hours, opts)?;
    let mut tests = Vec::new();
    for (i, (key, name, _)) in TESTS.iter().enumerate() {
        let mut t = fit_threshold(name, key, &c.maxima[i], &logs, hours, opts)?;
        // A CUSUM threshold so high that its mean run length between false alarms overflows
        // is out of reach of any fault as well: the fit's tail is heavier than the statistic
        // can carry (bursts of transient model error). Capped where the passes ran, several
        // times the largest value seen (`fit_threshold` refused data above it).
        if key.ends_with("cusum_threshold") || *key == "noise_threshold" {
            t.threshold = t.threshold.min(UNREACHABLE_CUSUM);
        }
        tests.push(t);
    }
    let mut keys: Vec<(&str, f64)> = values.to_vec();
    keys.extend(tests.iter().map(|t| (t.key, t.threshold)));
    let intake_toml = with_monitor_keys(&text, &origin, &keys)?;
    // The configuration written must build a monitor.
    let (cfg, _) = runtime_with(base, work.path(), &intake_toml)?;
    fdd_monitor::runtime::Runtime::new(&cfg).map_err(|e| CalibrateError::Toml {
        origin: "the calibrated intake.toml".into(),
        message: e.to_string(),
    })?;
    let runtime_toml = runtime_naming(base, "intake_config", "intake.toml")?;
    Ok(IntakeCalibration {
        logs,
        hours,
        map_noise_pa,
        maf_noise_rel,
        noise_samples,
        correction_dev,
        adapt_limit,
        tests,
        intake_toml,
        runtime_toml,
    })
}

impl IntakeCalibration {
    /// The report `fdd calibrate` prints (after the common header).
    pub fn render_body(&self, s: &mut String) {
        use std::fmt::Write as _;
        let _ = writeln!(
            s,
            "noise: MAP {:.0} Pa, MAF {:.2} % of the reading (std, robust scale of steady noise differences: {} and {})",
            self.map_noise_pa,
            100.0 * self.maf_noise_rel,
            self.noise_samples[0],
            self.noise_samples[1]
        );
        let _ = writeln!(
            s,
            "learned corrections: MAF up to {:.2} %, throttle up to {:.2} % off 1; adapt_limit {:.3}",
            100.0 * self.correction_dev[0],
            100.0 * self.correction_dev[1],
            self.adapt_limit
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;

    // A slow ramp with white noise of 800 Pa, a component alternating by +-700 Pa from one
    // sample to the next (intake pulsation aliased by the segment sampling) and, every 500
    // samples, a step of 30 kPa (a transient the steady filter let through): the robust scale
    // finds the noise (a second difference would read the alternation as noise: about
    // 1.3 kPa); the plain root mean square would be dominated by the steps.
    #[test]
    fn the_robust_scale_of_noise_differences_is_the_noise_std() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(5);
        let mut d = NoiseDiff::default();
        for k in 0..20_000 {
            let step = if (k / 500) % 2 == 1 { 30e3 } else { 0.0 };
            let n: f64 = rng.sample(StandardNormal);
            let alternating = if k % 2 == 0 { 700.0 } else { -700.0 };
            d.push(
                50e3 + 0.5 * k as f64 + step + alternating + 800.0 * n,
                true,
                false,
            );
        }
        let s = d.std();
        assert!((s - 800.0).abs() < 24.0, "{s}");
        let rms = (d.values.iter().map(|x| x * x).sum::<f64>() / d.values.len() as f64).sqrt();
        assert!(
            rms > 1.2 * 800.0,
            "the steps should spoil the plain estimate: {rms}"
        );
        // Relative: 2 % noise on a level of 10 g/s.
        let mut d = NoiseDiff::default();
        for _ in 0..20_000 {
            let n: f64 = rng.sample(StandardNormal);
            d.push(0.01 * (1.0 + 0.02 * n), true, true);
        }
        assert!((d.std() - 0.02).abs() < 6e-4, "{}", d.std());
        // Too few values: no estimate.
        let mut d = NoiseDiff::default();
        for k in 0..100 {
            d.push(f64::from(k), true, false);
        }
        assert!(d.std().is_nan());
    }
}
