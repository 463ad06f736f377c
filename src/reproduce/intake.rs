//! Reproduction of the MAP/MAF EKF paper's comparison (shared/REFERENCE.md §2, Tables 1 and 2)
//! with known truth: RMSE of manifold pressure `p_m` and of intake-valve air flow `W_inv` for the
//! centralized EKF, the paper's (naive) decentralized EKF pair, the federated filter
//! (fusion-reset), and the raw sensors, over a transient drive profile.
//!
//! Protocol (fixed so that results are comparable):
//! - truth: [`IntakeSim::from_scenario`], the truth simulator's own plant
//!   (`fixtures/plants/intake.toml`, unperturbed: the nominal physics of the
//!   `config/intake.toml` model the filters use) with a seeded `tip_in_out` profile
//!   (repeated tip-ins and tip-outs with speed changes, EGR at [`IntakeSettings::egr_pos`]
//!   during tip-outs), no fault, default pulsation and sensor noise (MAP 700 Pa, MAF 1.5 %);
//! - filters: the paper's filter model ([`ThrottleFlow::RandomWalk`]), input `frame.input()`
//!   (`[N, throttle, egr_cmd]`), measurements the frame's MAP and MAF; each segment is one
//!   predict + update. Start at the model's equilibrium of the first frame's input;
//! - estimates: `p_m = x[0]`, `W_inv = intake_valve_flow(x[0], N)`; raw baselines: `p_m` = MAP,
//!   `W_inv` = `intake_valve_flow(MAP, N)`, and the MAF reading taken as a flow measure;
//! - errors against `frame.truth` (`p_m`, `w_inv`) at every segment; the cost is the wall time of
//!   each filter's loop alone (estimates written to a preallocated buffer) divided by segments.
//!
//! Filter settings (documented constants, not configuration: `config/intake.toml` is parsed with
//! `deny_unknown_fields`): see [`Q_STD`], [`P0_STD_REL`], [`FEDERATED_SHARES`]. `R` comes from the
//! configured sensor noise: `R_map = map_noise_std^2`; the MAF noise is relative (1.5 % of the
//! reading), which a constant `R` cannot express, so `R_maf = (maf_noise_rel * W_rms)^2` with
//! `W_rms` the RMS of the MAF readings over the run (sensor data, not truth): then the mean
//! normalized MAF noise `E[v^2] / R_maf` is 1 over the profile.

use std::time::{Duration, Instant};

use fdd_estimators::models::intake::{
    IntakeModel, MafSensor, MapMafSensors, MapSensor, ThrottleFlow, X_PM, X_WTHR,
};
use fdd_estimators::{
    ConfigError as FilterConfigError, DecentralizedPair, Ekf, FederatedFilter, FusionNoise,
};
use fdd_fixtures::intake_profile::{ProfileSpec, TipInOutSpec};
use fdd_fixtures::intake_sim::{
    default_intake_model, IntakeFault, IntakeFrame, IntakeScenario, IntakeSim,
};
use fdd_fixtures::scenario::ScenarioError;
use nalgebra::{Matrix1, Matrix2, SMatrix, SVector, Vector1, Vector2};

/// Process noise standard deviations per segment of `[p_m (Pa), p_mes (Pa), W_thr (kg/s),
/// W_mes (kg/s), q1 (Pa), q2 (Pa/s)]`. The random walk on `W_thr` carries the tip-ins (the
/// paper's filter has no throttle model); tuned so that the centralized / federated mean NIS
/// is within 10 % of 2 on the default profile.
pub const Q_STD: [f64; 6] = [150.0, 20.0, 2.1e-3, 3e-5, 200.0, 6e4];

/// Initial standard deviations relative to the initial state's magnitudes: `p` states 2 kPa,
/// flows 10 % of the initial throttle flow, pulsation 1 kPa and 1e5 Pa/s.
pub const P0_STD_REL: [f64; 6] = [2e3, 2e3, 0.1, 0.1, 1e3, 1e5];

/// Information-sharing factors `beta` of the federated filter (MAP local, MAF local).
pub const FEDERATED_SHARES: [f64; 2] = [0.5, 0.5];

/// Paper's Table 1 (pressure RMSE, Pa) and Table 2 (flow RMSE, kg/s) against the ECU values:
/// `(centralized, decentralized, sensor)`.
pub const PAPER_PRESSURE_RMSE: (f64, f64, f64) = (3.27e3, 3.31e3, 3.21e3);
/// See [`PAPER_PRESSURE_RMSE`].
pub const PAPER_FLOW_RMSE: (f64, f64, f64) = (7.56e-4, 7.58e-4, 8.30e-4);

/// What to run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntakeSettings {
    /// Length of the drive (s).
    pub duration_s: f64,
    /// Seed of profile, process and sensor noise.
    pub seed: u64,
    /// EGR command during tip-out legs (0 = no EGR).
    pub egr_pos: f64,
}

impl Default for IntakeSettings {
    fn default() -> Self {
        Self {
            duration_s: 120.0,
            seed: 1,
            egr_pos: 0.3,
        }
    }
}

/// One row of the table.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimatorRow {
    pub name: &'static str,
    /// RMSE of `p_m` (Pa); `None` where the row does not estimate it (MAF).
    pub rmse_pm_pa: Option<f64>,
    /// RMSE of `W_inv` (kg/s).
    pub rmse_winv_kg_s: f64,
    /// Mean NIS and its degrees of freedom (filters only).
    pub mean_nis: Option<(f64, usize)>,
    /// Wall time per segment of the filter loop (filters only).
    pub ns_per_step: Option<f64>,
    /// Steps a filter refused (estimate carried over).
    pub rejected_steps: u64,
    /// The paper's `(pressure, flow)` RMSE for this row, if it reports one.
    pub paper: Option<(f64, f64)>,
}

/// The whole report.
#[derive(Debug, Clone, PartialEq)]
pub struct IntakeReport {
    pub settings: IntakeSettings,
    pub segments: usize,
    /// Centralized, decentralized, federated, MAP sensor, MAF sensor (in this order).
    pub rows: Vec<EstimatorRow>,
    /// `R` in use: MAP (Pa^2), MAF (kg^2/s^2).
    pub r_map: f64,
    pub r_maf: f64,
    /// Wall time of the truth simulation.
    pub sim_time: Duration,
}

impl IntakeReport {
    /// The row named `name`.
    pub fn row(&self, name: &str) -> Option<&EstimatorRow> {
        self.rows.iter().find(|r| r.name == name)
    }
}

/// Errors that stop the reproduction.
#[derive(Debug, thiserror::Error)]
pub enum IntakeError {
    #[error("filter configuration rejected: {0}")]
    Filter(#[from] FilterConfigError),
    #[error("scenario: {0}")]
    Scenario(#[from] ScenarioError),
    #[error("invalid setting `{name}`: {reason}")]
    Setting { name: &'static str, reason: String },
}

struct Acc {
    pm: f64,
    w: f64,
    nis: f64,
    n: usize,
}

impl Acc {
    fn new() -> Self {
        Self {
            pm: 0.0,
            w: 0.0,
            nis: 0.0,
            n: 0,
        }
    }
}

/// Checks the settings against the command line's ranges ([`crate::limits`]): every frame of
/// the drive is kept in memory.
fn check(s: &IntakeSettings) -> Result<(), IntakeError> {
    use crate::limits::{INTAKE_DURATION, INTAKE_EGR};
    INTAKE_DURATION
        .check(s.duration_s)
        .map_err(|reason| IntakeError::Setting {
            name: "duration",
            reason,
        })?;
    INTAKE_EGR
        .check(s.egr_pos)
        .map_err(|reason| IntakeError::Setting {
            name: "egr",
            reason,
        })?;
    Ok(())
}

/// Runs the comparison.
pub fn run(s: &IntakeSettings) -> Result<IntakeReport, IntakeError> {
    check(s)?;
    // The filters' model is the monitor's (config/intake.toml); the truth is the plant file's.
    let filter_model = default_intake_model();
    let model = IntakeModel::new(filter_model.params().clone(), ThrottleFlow::RandomWalk).map_err(
        |reason| IntakeError::Setting {
            name: "model",
            reason,
        },
    )?;
    let profile = ProfileSpec::TipInOut(TipInOutSpec {
        egr_pos: s.egr_pos,
        ..TipInOutSpec::default()
    });
    let scenario = IntakeScenario::new(
        "reproduce_intake",
        s.duration_s,
        s.seed,
        profile,
        IntakeFault::None,
    );
    let t0 = Instant::now();
    let sim = IntakeSim::from_scenario(&scenario)?;
    let (map_std, maf_rel) = sim.noise();
    let frames: Vec<IntakeFrame> = sim.collect();
    let sim_time = t0.elapsed();
    if frames.is_empty() {
        return Err(IntakeError::Setting {
            name: "duration",
            reason: "no segment simulated".into(),
        });
    }

    // Filter settings.
    let u0 = frames[0].input();
    let x0 = model.equilibrium(&u0).ok_or_else(|| IntakeError::Setting {
        name: "profile",
        reason: format!("no equilibrium at the first input {u0:?}"),
    })?;
    let w0 = x0[X_WTHR].abs().max(1e-4);
    let p0_std = SVector::<f64, 6>::from([
        P0_STD_REL[0],
        P0_STD_REL[1],
        P0_STD_REL[2] * w0,
        P0_STD_REL[3] * w0,
        P0_STD_REL[4],
        P0_STD_REL[5],
    ]);
    let p0 = SMatrix::<f64, 6, 6>::from_diagonal(&p0_std.component_mul(&p0_std));
    let q_std = SVector::<f64, 6>::from(Q_STD);
    let q = SMatrix::<f64, 6, 6>::from_diagonal(&q_std.component_mul(&q_std));
    let w_rms =
        (frames.iter().map(|f| f.maf_kg_s * f.maf_kg_s).sum::<f64>() / frames.len() as f64).sqrt();
    let r_map = map_std * map_std;
    let r_maf = (maf_rel * w_rms).powi(2);
    let noise = FusionNoise {
        q,
        r1: Matrix1::new(r_map),
        r2: Matrix1::new(r_maf),
    };

    let n = frames.len();
    let mut est = vec![(0.0_f64, 0.0_f64); n];

    // Centralized EKF.
    let mut ekf = Ekf::new(
        model.clone(),
        MapMafSensors,
        x0,
        p0,
        q,
        Matrix2::from_diagonal(&Vector2::new(r_map, r_maf)),
    )?;
    let t = Instant::now();
    let mut rej = 0;
    for (f, e) in frames.iter().zip(est.iter_mut()) {
        let u = f.input();
        let y = Vector2::new(f.map_pa, f.maf_kg_s);
        let r = ekf.predict(&u).and_then(|()| ekf.update(&y, &u));
        match r {
            Ok(inn) => *e = (ekf.state()[X_PM], inn.nis),
            Err(_) => {
                rej += 1;
                *e = (ekf.state()[X_PM], f64::NAN);
            }
        }
    }
    let cen = score(
        "centralized EKF",
        &model,
        &frames,
        &est,
        t.elapsed(),
        2,
        rej,
    );

    // Decentralized pair (paper's naive fusion).
    let mut pair = DecentralizedPair::new(model.clone(), MapSensor, MafSensor, x0, p0, noise)?;
    let t = Instant::now();
    let mut rej = 0;
    for (f, e) in frames.iter().zip(est.iter_mut()) {
        let u = f.input();
        match pair.step(&u, &Vector1::new(f.map_pa), &Vector1::new(f.maf_kg_s)) {
            Ok(st) => *e = (st.x[X_PM], st.nis),
            Err(_) => {
                rej += 1;
                *e = (pair.state()[X_PM], f64::NAN);
            }
        }
    }
    let dec = score(
        "decentralized EKF",
        &model,
        &frames,
        &est,
        t.elapsed(),
        2,
        rej,
    );

    // Federated (fusion-reset).
    let mut fed = FederatedFilter::new(
        model.clone(),
        MapSensor,
        MafSensor,
        x0,
        p0,
        noise,
        FEDERATED_SHARES,
    )?;
    let t = Instant::now();
    let mut rej = 0;
    for (f, e) in frames.iter().zip(est.iter_mut()) {
        let u = f.input();
        match fed.step(&u, &Vector1::new(f.map_pa), &Vector1::new(f.maf_kg_s)) {
            Ok(st) => *e = (st.x[X_PM], st.nis),
            Err(_) => {
                rej += 1;
                *e = (fed.state()[X_PM], f64::NAN);
            }
        }
    }
    let fedr = score("federated EKF", &model, &frames, &est, t.elapsed(), 2, rej);

    // Raw sensors.
    let mut map = Acc::new();
    let mut maf = Acc::new();
    for f in &frames {
        let d = f.map_pa - f.truth.p_m;
        map.pm += d * d;
        let dw = model.intake_valve_flow(f.map_pa, f.n_rpm) - f.truth.w_inv;
        map.w += dw * dw;
        let dm = f.maf_kg_s - f.truth.w_inv;
        maf.w += dm * dm;
    }
    let nf = n as f64;
    let map_row = EstimatorRow {
        name: "MAP sensor",
        rmse_pm_pa: Some((map.pm / nf).sqrt()),
        rmse_winv_kg_s: (map.w / nf).sqrt(),
        mean_nis: None,
        ns_per_step: None,
        rejected_steps: 0,
        paper: Some((PAPER_PRESSURE_RMSE.2, PAPER_FLOW_RMSE.2)),
    };
    let maf_row = EstimatorRow {
        name: "MAF sensor",
        rmse_pm_pa: None,
        rmse_winv_kg_s: (maf.w / nf).sqrt(),
        mean_nis: None,
        ns_per_step: None,
        rejected_steps: 0,
        paper: None,
    };
    let mut cen = cen;
    cen.paper = Some((PAPER_PRESSURE_RMSE.0, PAPER_FLOW_RMSE.0));
    let mut dec = dec;
    dec.paper = Some((PAPER_PRESSURE_RMSE.1, PAPER_FLOW_RMSE.1));
    Ok(IntakeReport {
        settings: *s,
        segments: n,
        rows: vec![cen, dec, fedr, map_row, maf_row],
        r_map,
        r_maf,
        sim_time,
    })
}

fn score(
    name: &'static str,
    model: &IntakeModel,
    frames: &[IntakeFrame],
    est: &[(f64, f64)],
    wall: Duration,
    dof: usize,
    rejected_steps: u64,
) -> EstimatorRow {
    let mut a = Acc::new();
    for (f, &(pm, nis)) in frames.iter().zip(est) {
        let d = pm - f.truth.p_m;
        a.pm += d * d;
        let dw = model.intake_valve_flow(pm, f.n_rpm) - f.truth.w_inv;
        a.w += dw * dw;
        if nis.is_finite() {
            a.nis += nis;
            a.n += 1;
        }
    }
    let nf = frames.len() as f64;
    EstimatorRow {
        name,
        rmse_pm_pa: Some((a.pm / nf).sqrt()),
        rmse_winv_kg_s: (a.w / nf).sqrt(),
        mean_nis: Some((a.nis / a.n.max(1) as f64, dof)),
        ns_per_step: Some(wall.as_nanos() as f64 / nf),
        rejected_steps,
        paper: None,
    }
}

/// The report as a text table.
pub fn render(r: &IntakeReport) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let s = &r.settings;
    let _ = writeln!(
        out,
        "MAP/MAF EKF comparison (REFERENCE §2, Tables 1-2) with known truth: tip_in_out {} s, \
         seed {}, EGR {} on tip-outs, {} segments",
        s.duration_s, s.seed, s.egr_pos, r.segments
    );
    let _ = writeln!(
        out,
        "{:<18} {:>12} {:>12} {:>14} {:>14} {:>9} {:>9} {:>8}",
        "estimator",
        "RMSE p_m Pa",
        "paper T1 Pa",
        "RMSE W_inv kg/s",
        "paper T2 kg/s",
        "NIS/dof",
        "ns/step",
        "rejected"
    );
    for e in &r.rows {
        let (pp, pw) = match e.paper {
            Some((p, w)) => (format!("{p:.3e}"), format!("{w:.3e}")),
            None => ("-".into(), "-".into()),
        };
        let pm = e.rmse_pm_pa.map_or("-".into(), |v| format!("{v:.1}"));
        let nis = e
            .mean_nis
            .map_or("-".into(), |(m, d)| format!("{m:.2}/{d}"));
        let ns = e.ns_per_step.map_or("-".into(), |v| format!("{v:.0}"));
        let _ = writeln!(
            out,
            "{:<18} {:>12} {:>12} {:>14.3e} {:>14} {:>9} {:>9} {:>8}",
            e.name, pm, pp, e.rmse_winv_kg_s, pw, nis, ns, e.rejected_steps
        );
    }
    let _ = writeln!(
        out,
        "R: MAP {:.0} Pa^2 ({:.0} Pa std), MAF {:.3e} (kg/s)^2 (1.5 % of the RMS reading); \
         truth simulation {:.2} s",
        r.r_map,
        r.r_map.sqrt(),
        r.r_maf,
        r.sim_time.as_secs_f64()
    );
    let _ = writeln!(
        out,
        "The paper's errors are against the ECU's values; ours against the simulated truth. \
         MAP-sensor W_inv = valve-flow map at the raw MAP; MAF sensor = reading taken as W_inv. \
         Decentralized NIS = sum of the two local NIS (its fused covariance is optimistic)."
    );
    out
}
