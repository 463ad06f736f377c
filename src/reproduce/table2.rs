//! Reproduction of Table II of the wattmeter throttle paper: how well UKFs fed by a wattmeter
//! alone (`y = i^2 + v`) track the throttle plate angle, on a simulated throttle with known truth.
//!
//! Protocol (fixed so results are comparable): excitation from
//! [`fdd_fixtures::excitation::PulseTrainSpec::table2`]; truth = the model with per-step
//! process noise `scale * F w` and the plate stops; measurement `i^2 + W v`; filters start at
//! `x0 = 0`, `P0` from the config. The error is estimated minus true angle (deg) after each
//! measurement update, over every sample.

use std::time::{Duration, Instant};

use fdd_estimators::models::throttle::{ThrottleModel, Wattmeter};
use fdd_estimators::particle::ParticleFilter;
use fdd_estimators::reacquire::Reacquire;
use fdd_estimators::{ConfigError as FilterConfigError, SigmaPoints, Ukf};
use fdd_fixtures::excitation::{PulseTrain, PulseTrainSpec};
use fdd_fixtures::throttle_truth::ThrottleTruth;
use nalgebra::{Matrix1, Matrix3, Vector1, Vector3};

use crate::config::ThrottleConfig;
use crate::stats::RunningStats;

/// What to run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Table2Settings {
    pub samples: usize,
    pub seed: u64,
    /// Standard deviation of the wattmeter noise (A^2).
    pub wattmeter_std: f64,
    /// Particles of the reference particle filter; `None` skips it.
    pub particles: Option<usize>,
}

/// Error statistics of one estimator.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimatorResult {
    pub name: &'static str,
    /// Error of estimated minus true angle (deg).
    pub error: RunningStats,
    /// Steps a filter refused (error value returned); the estimate is carried over for those.
    pub rejected_steps: u64,
    /// Times the filter was found inconsistent and re-seeded at the static map.
    pub reseeds: u64,
    /// Paper's simulated mean and std (deg), when the paper reports this estimator.
    pub paper: Option<(f64, f64)>,
}

/// The whole report.
#[derive(Debug, Clone, PartialEq)]
pub struct Table2Report {
    pub settings: Table2Settings,
    pub ukfs: Vec<EstimatorResult>,
    pub particle_filter: Option<EstimatorResult>,
    /// Share of samples whose true angle lies in mode 1, 2, 3.
    pub mode_share: [f64; 3],
    /// Wall time of the simulation and the three UKFs.
    pub ukf_wall_time: Duration,
    /// Wall time of the particle filter pass.
    pub particle_wall_time: Option<Duration>,
}

/// Errors that stop the reproduction.
#[derive(Debug, thiserror::Error)]
pub enum Table2Error {
    #[error("filter configuration rejected: {0}")]
    Filter(#[from] FilterConfigError),
    #[error("excitation: {0}")]
    Excitation(#[from] fdd_fixtures::butterworth::CutoffError),
    #[error("invalid setting `{name}`: {reason}")]
    Setting { name: &'static str, reason: String },
}

fn diag(v: [f64; 3]) -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::from(v))
}

/// Data source shared by the UKF pass and the particle-filter pass: the same seed gives both
/// the same excitation, truth and measurements.
struct Scenario {
    excitation: PulseTrain,
    truth: ThrottleTruth,
}

impl Scenario {
    fn new(
        cfg: &ThrottleConfig,
        model: ThrottleModel,
        s: &Table2Settings,
    ) -> Result<Self, Table2Error> {
        let t = cfg.truth;
        let f = Vector3::from(t.process_noise_f_diag) * t.process_noise_scale;
        Ok(Self {
            excitation: PulseTrain::new(PulseTrainSpec::table2(), s.seed)?,
            truth: ThrottleTruth::new(model, Vector3::zeros(), f, s.wattmeter_std, s.seed),
        })
    }

    fn next(&mut self) -> fdd_fixtures::throttle_truth::ThrottleSample {
        let u = self.excitation.next_sample();
        self.truth.step(u)
    }
}

/// Checks the settings against the command line's ranges ([`crate::limits`]): a sample or
/// particle count beyond them would run for days or fail to allocate.
fn check_settings(s: &Table2Settings) -> Result<(), Table2Error> {
    use crate::limits::{TABLE2_PARTICLES, TABLE2_SAMPLES, TABLE2_WATTMETER_STD};
    let count = |n: usize| u64::try_from(n).unwrap_or(u64::MAX);
    let setting = |name: &'static str| move |reason: String| Table2Error::Setting { name, reason };
    TABLE2_SAMPLES
        .check(count(s.samples))
        .map_err(setting("samples"))?;
    TABLE2_WATTMETER_STD
        .check(s.wattmeter_std)
        .map_err(setting("wattmeter-std"))?;
    if let Some(p) = s.particles {
        TABLE2_PARTICLES
            .check(count(p))
            .map_err(setting("particles"))?;
    }
    Ok(())
}

/// One sample as every wattmeter UKF sees it.
struct Step<'a> {
    u: &'a Vector1<f64>,
    y: &'a Vector1<f64>,
    truth_deg: f64,
    /// Where a filter that has lost track is re-seeded: the static map at the recent voltage.
    reseed_state: Vector3<f64>,
    reseed_covariance: &'a Matrix3<f64>,
}

impl Step<'_> {
    /// Same sequence for each filter: correct with y_k, re-seed if inconsistent, score, predict
    /// with u_k. A refused step keeps the previous estimate and is counted.
    fn run<const L: usize>(
        &self,
        f: &mut Ukf<ThrottleModel, Wattmeter, 3, 1, 1, L>,
        monitor: &mut Reacquire,
        res: &mut EstimatorResult,
    ) {
        let mut ok = match f.update(self.y, self.u) {
            Ok(inn) => {
                if monitor.observe(inn.nis, inn.dof) {
                    res.reseeds += 1;
                    f.reset(self.reseed_state, *self.reseed_covariance).is_ok()
                } else {
                    true
                }
            }
            Err(_) => false,
        };
        res.error
            .push(f.transition_model().angle_deg(f.state()) - self.truth_deg);
        ok &= f.predict(self.u).is_ok();
        if !ok {
            res.rejected_steps += 1;
        }
    }
}

/// Runs the protocol.
pub fn run(cfg: &ThrottleConfig, s: &Table2Settings) -> Result<Table2Report, Table2Error> {
    check_settings(s)?;
    let model = ThrottleModel::new(cfg.model).map_err(|reason| Table2Error::Setting {
        name: "model",
        reason,
    })?;
    let w = cfg.wattmeter_ukf;
    let p0 = diag(w.p0_diag);
    let q = diag(w.q_diag);
    let r = Matrix1::new(s.wattmeter_std * s.wattmeter_std + w.r_floor);
    let x0 = Vector3::zeros();
    let mut ahsm = Ukf::<_, _, 3, 1, 1, 7>::new(
        model,
        Wattmeter,
        SigmaPoints::ahsm(w.ahsm_lambda)?,
        x0,
        p0,
        q,
        r,
    )?;
    let mut arm =
        Ukf::<_, _, 3, 1, 1, 4>::new(model, Wattmeter, SigmaPoints::arm(w.arm_w0)?, x0, p0, q, r)?;
    let mut agm = Ukf::<_, _, 3, 1, 1, 4>::new(
        model,
        Wattmeter,
        SigmaPoints::agm(&Vector3::from(w.agm_v))?,
        x0,
        p0,
        q,
        r,
    )?;

    let mut scenario = Scenario::new(cfg, model, s)?;
    let mut results = [
        EstimatorResult {
            name: "UKF-AHSM",
            error: RunningStats::default(),
            rejected_steps: 0,
            reseeds: 0,
            paper: Some((-0.090, 4.002)),
        },
        EstimatorResult {
            name: "UKF-ARM",
            error: RunningStats::default(),
            rejected_steps: 0,
            reseeds: 0,
            paper: Some((-0.071, 4.061)),
        },
        EstimatorResult {
            name: "UKF-AGM",
            error: RunningStats::default(),
            rejected_steps: 0,
            reseeds: 0,
            paper: Some((-0.078, 3.983)),
        },
    ];
    let mut mode_count = [0u64; 3];
    // Input low-pass for re-seeding: the plate settles in tens of milliseconds, so the static map
    // is evaluated at the recently applied voltage, not the instantaneous one.
    let u_alpha = (model.params().dt_s / w.reseed_input_tau_s).min(1.0);
    let mut u_slow = 0.0;
    let mut re = [Reacquire::new(
        w.reacquire_window,
        w.reacquire_threshold,
        w.reacquire_holdoff,
    )?; 3];
    let start = Instant::now();
    for _ in 0..s.samples {
        let smp = scenario.next();
        let u = Vector1::new(smp.u);
        u_slow += (smp.u - u_slow) * u_alpha;
        let y = Vector1::new(smp.wattmeter);
        let truth_deg = model.angle_deg(&smp.x);
        mode_count[model.mode(&smp.x)] += 1;
        let step = Step {
            u: &u,
            y: &y,
            truth_deg,
            reseed_state: model.equilibrium(u_slow),
            reseed_covariance: &p0,
        };
        step.run(&mut ahsm, &mut re[0], &mut results[0]);
        step.run(&mut arm, &mut re[1], &mut results[1]);
        step.run(&mut agm, &mut re[2], &mut results[2]);
    }
    let ukf_wall_time = start.elapsed();
    let total = s.samples as f64;
    let mode_share = mode_count.map(|c| c as f64 / total);

    let (particle_filter, particle_wall_time) = match s.particles {
        None => (None, None),
        Some(count) => {
            let start = Instant::now();
            let res = run_particle_filter(cfg, model, s, count)?;
            (Some(res), Some(start.elapsed()))
        }
    };
    Ok(Table2Report {
        settings: *s,
        ukfs: results.to_vec(),
        particle_filter,
        mode_share,
        ukf_wall_time,
        particle_wall_time,
    })
}

/// Bootstrap particle filter on the same data, with the truth's own noise model: the reference
/// for what any estimator can reach on this protocol.
fn run_particle_filter(
    cfg: &ThrottleConfig,
    model: ThrottleModel,
    s: &Table2Settings,
    count: usize,
) -> Result<EstimatorResult, Table2Error> {
    let t = cfg.truth;
    let g = diag(t.process_noise_f_diag) * t.process_noise_scale;
    let r = Matrix1::new(s.wattmeter_std * s.wattmeter_std);
    // The truth starts at rest with the plate closed; the PF is told the same prior as the UKFs.
    let p0 = diag(cfg.wattmeter_ukf.p0_diag);
    let mut pf = ParticleFilter::new(
        model,
        Wattmeter,
        count,
        Vector3::zeros(),
        p0,
        g,
        r,
        s.seed ^ 0x9f,
    )?;
    let mut scenario = Scenario::new(cfg, model, s)?;
    let mut res = EstimatorResult {
        name: "particle filter",
        error: RunningStats::default(),
        rejected_steps: 0,
        reseeds: 0,
        paper: None,
    };
    for _ in 0..s.samples {
        let smp = scenario.next();
        let u = Vector1::new(smp.u);
        let ok = pf.update(&Vector1::new(smp.wattmeter), &u).is_ok();
        res.error
            .push(model.angle_deg(&pf.mean()) - model.angle_deg(&smp.x));
        if !(pf.predict(&u).is_ok() && ok) {
            res.rejected_steps += 1;
        }
    }
    Ok(res)
}

/// Formats the report as a plain-text table.
pub fn render(r: &Table2Report) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let s = &r.settings;
    let _ = writeln!(
        out,
        "Table II reproduction: {} samples at 1 ms, seed {}, wattmeter noise std {} A^2",
        s.samples, s.seed, s.wattmeter_std
    );
    let _ = writeln!(
        out,
        "{:<18} {:>10} {:>10} {:>12} {:>12} {:>9} {:>8}",
        "estimator", "mean deg", "std deg", "paper mean", "paper std", "rejected", "reseeds"
    );
    let rows = r.ukfs.iter().chain(r.particle_filter.iter());
    for e in rows {
        let (pm, ps) = match e.paper {
            Some((m, sd)) => (format!("{m:.3}"), format!("{sd:.3}")),
            None => ("-".into(), "-".into()),
        };
        let _ = writeln!(
            out,
            "{:<18} {:>10.3} {:>10.3} {:>12} {:>12} {:>9} {:>8}",
            e.name,
            e.error.mean(),
            e.error.std(),
            pm,
            ps,
            e.rejected_steps,
            e.reseeds
        );
    }
    let _ = writeln!(
        out,
        "mode share (true angle): [0,8] deg {:.1}%, (8,16] deg {:.1}%, (16,90] deg {:.1}%",
        100.0 * r.mode_share[0],
        100.0 * r.mode_share[1],
        100.0 * r.mode_share[2]
    );
    let _ = writeln!(
        out,
        "wall time (simulation + 3 UKFs): {:.3} s",
        r.ukf_wall_time.as_secs_f64()
    );
    if let Some(t) = r.particle_wall_time {
        let _ = writeln!(
            out,
            "wall time (particle filter pass): {:.3} s",
            t.as_secs_f64()
        );
    }
    out
}
