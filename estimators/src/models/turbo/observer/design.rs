//! The observer's gains, designed offline as in the paper (§3): at each grid node (engine speed,
//! intake manifold pressure) the model's stationary operating point, its linearization
//! discretized at the sample time, the state noise from the model's quality at the engine map's
//! stationary points and the measurement noise from stationary measurements, and the stationary
//! Kalman gain of that linear system ([`crate::dare::stationary_kalman`]).
//!
//! # Operating points
//!
//! A node fixes the engine speed and the intake manifold pressure; the throttle and the
//! wastegate that produce it follow one actuator path `s` in `[0, 2]`, the usual order of a
//! torque-based air-path controller: up to `s = 1` the throttle opens (`100 s` %) with the
//! wastegate open (fully by default; at the engine's part-load opening with
//! [`ActuatorPath`]); beyond it the throttle is wide open and the wastegate closes to build
//! boost. The stationary `p_im` rises with `s` along this path; a node whose pressure the
//! path does not reach at that speed (above full boost, below the closed throttle) is
//! infeasible and takes the gains of the nearest feasible node at the same speed.
//!
//! # Noise (paper §3.3)
//!
//! - **State noise**: `Q_i = (x_meas,i - x_stat,i)^2`, the squared stationary model error of
//!   each state at the engine map's points ([`state_noise_from_map`]); a node takes the mean
//!   over the [`NEAREST_MAP_POINTS`] map points nearest to it in (speed, pressure), each axis
//!   normalized by its range. A volume's mass error is its pressure error through
//!   `M = p V / (R T)`. States the map does not measure take stated substitutes (see
//!   [`state_noise_from_map`]); every entry has a floor, [`Q_FLOOR_FRACTION`] of the state's
//!   scale, so that no state is taken as exact. An engine without a map (LiU-ICE) takes the
//!   same errors at the quasi-stationary samples of a fault-free driving log
//!   ([`state_noise_from_log`]).
//! - **Measurement noise**: `R_i` = the variance of a stationary measurement about its mean
//!   (with a floor), supplied by the caller ([`DesignOptions::r`]).
//! - **Time**: the paper's observer is continuous, `dx/dt = f + K (y - h)`, and its `Q` and `R`
//!   are spectral densities over a time unit of 1 s. The discrete filter equivalent at sample
//!   time `dt` has `Q_d = Q dt` and `R_d = R / dt` (process noise integrated over the sample,
//!   measurement noise averaged over it), which makes the discrete gains approach the
//!   continuous filter's as `dt -> 0` rather than depend on the sample rate.

use nalgebra::SMatrix;
use thiserror::Error;

use super::gains::{GainTable, GainTableError};
use super::{measurement, Sensor};
use crate::dare::{stationary_kalman, DareError};
use crate::models::turbo::discrete::TurboDiscrete14;
use crate::models::turbo::fit::{CheckReport, EnginePoint};
use crate::models::turbo::{
    TurboError, TurboInput, TurboModel, TurboState, TurboStateAugmented, N_STATES,
    N_STATES_AUGMENTED, X_DC_ETA_VOL, X_M_AF, X_M_C, X_M_EM, X_M_ES, X_M_IC, X_M_IM, X_OMEGA_T,
    X_T_AF, X_T_C, X_T_EM, X_T_ES, X_T_IC, X_T_IM,
};
use crate::param::ParamError;

/// Map points averaged for a node's state noise.
pub const NEAREST_MAP_POINTS: usize = 4;
/// Floor of each state-noise standard deviation, as a fraction of the state's scale
/// ([`TurboModel::state_scales`]): 0.1 %.
pub const Q_FLOOR_FRACTION: f64 = 1e-3;
/// Samples of the actuator path per speed before the nodes are refined.
const PATH_SAMPLES: usize = 60;
/// Relative tolerance on a node's pressure.
const PRESSURE_TOL: f64 = 1e-4;

/// A failed design.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DesignError {
    /// The model refused an operating point or did not converge.
    #[error("observer design at {speed_rad_s} rad/s: {source}")]
    Model {
        /// The node's speed.
        speed_rad_s: f64,
        /// The model's error.
        source: TurboError,
    },
    /// No node at this speed is reachable.
    #[error("observer design: no pressure node is reachable at {speed_rad_s} rad/s (stationary p_im {lo_pa:.0} .. {hi_pa:.0} Pa along the actuator path)")]
    Unreachable {
        /// The speed.
        speed_rad_s: f64,
        /// Lowest stationary pressure found.
        lo_pa: f64,
        /// Highest.
        hi_pa: f64,
    },
    /// The Riccati equation failed at a node.
    #[error("observer design at ({speed_rad_s} rad/s, {pressure_pa} Pa): {source}")]
    Dare {
        /// The node's speed.
        speed_rad_s: f64,
        /// The node's pressure.
        pressure_pa: f64,
        /// The solver's error.
        source: DareError,
    },
    /// A bad option.
    #[error("observer design: {0}")]
    Param(#[from] ParamError),
    /// The table could not be built.
    #[error(transparent)]
    Table(#[from] GainTableError),
    /// No map points for the state noise.
    #[error("observer design: no engine-map points to take the state noise from")]
    NoNoise,
}

/// The throttle (%) and wastegate (0 closed .. 1 open) at actuator-path position `s` on the
/// default path ([`ActuatorPath::default`]: the wastegate fully open while the throttle opens).
pub fn actuators(s: f64) -> (f64, f64) {
    ActuatorPath::default().actuators(s)
}

/// The actuator path the design's operating points follow (see the module docs): the throttle
/// opens with the wastegate at `wastegate_open`, then the wastegate closes from there at wide-open
/// throttle. An engine whose boost controller parks the wastegate part-open at part load (the
/// LiU-ICE engine's logged position is 0.61-0.65 whenever it is not closed) has its part-load
/// operating points, and so its linearizations, on that opening rather than fully open.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActuatorPath {
    /// The wastegate's position while the throttle opens (0 closed .. 1 open).
    pub wastegate_open: f64,
}

impl Default for ActuatorPath {
    /// Fully open (1): the generic order of a torque-based air-path controller.
    fn default() -> Self {
        Self {
            wastegate_open: 1.0,
        }
    }
}

impl ActuatorPath {
    /// The throttle (%) and wastegate at path position `s` in `[0, 2]` (clamped): up to 1 the
    /// throttle opens (`100 s` %) with the wastegate at [`Self::wastegate_open`]; beyond, the
    /// throttle is wide open and the wastegate closes linearly to 0 at `s = 2`.
    pub fn actuators(&self, s: f64) -> (f64, f64) {
        let s = s.clamp(0.0, 2.0);
        if s <= 1.0 {
            (100.0 * s, self.wastegate_open)
        } else {
            (100.0, self.wastegate_open * (2.0 - s))
        }
    }
}

/// A stationary operating point of the design grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OperatingPoint {
    /// Actuator-path position.
    pub s: f64,
    /// The input.
    pub input: TurboInput,
    /// The stationary state.
    pub state: TurboState,
    /// Its intake manifold pressure (Pa).
    pub p_im_pa: f64,
}

/// The ambient and mixture conditions of a design.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Conditions {
    /// Ambient pressure (Pa).
    pub ambient_pressure_pa: f64,
    /// Ambient temperature (K).
    pub ambient_temperature_k: f64,
    /// Normalized air/fuel ratio.
    pub lambda: f64,
}

fn point_at(
    model: &TurboModel,
    speed: f64,
    s: f64,
    c: &Conditions,
    path: &ActuatorPath,
    guess: Option<&TurboState>,
) -> Result<OperatingPoint, TurboError> {
    let (throttle_pct, wastegate_frac) = path.actuators(s);
    let input = TurboInput {
        throttle_pct,
        engine_speed_rad_s: speed,
        wastegate_frac,
        lambda: c.lambda,
        ambient_pressure_pa: c.ambient_pressure_pa,
        ambient_temperature_k: c.ambient_temperature_k,
    };
    let st = model
        .stationary_point(&input, guess)
        .or_else(|_| model.stationary_point(&input, None))?;
    let p_im_pa = model.signals(&st.state, &input).p_im_pa;
    Ok(OperatingPoint {
        s,
        input,
        state: st.state,
        p_im_pa,
    })
}

/// The operating points at engine speed `speed` whose stationary `p_im` equals each of
/// `targets_pa` (None where the actuator path does not reach it). Sweeps the path with warm
/// starts, then refines each bracketed target by regula falsi (Illinois).
pub fn operating_points(
    model: &TurboModel,
    speed: f64,
    targets_pa: &[f64],
    c: &Conditions,
    actuator_path: &ActuatorPath,
) -> Result<Vec<Option<OperatingPoint>>, DesignError> {
    let err = |source| DesignError::Model {
        speed_rad_s: speed,
        source,
    };
    let mut path: Vec<OperatingPoint> = Vec::with_capacity(PATH_SAMPLES + 1);
    let mut guess: Option<TurboState> = None;
    for k in 0..=PATH_SAMPLES {
        // Denser at small openings, where p_im changes fastest.
        let f = k as f64 / PATH_SAMPLES as f64;
        let s = 0.01 + 1.99 * f * f.sqrt();
        let p = point_at(model, speed, s, c, actuator_path, guess.as_ref()).map_err(err)?;
        guess = Some(p.state);
        path.push(p);
    }
    let mut out = Vec::with_capacity(targets_pa.len());
    for &target in targets_pa {
        let bracket = path
            .windows(2)
            .find(|w| (w[0].p_im_pa - target) * (w[1].p_im_pa - target) <= 0.0);
        let Some(w) = bracket else {
            out.push(None);
            continue;
        };
        let (mut a, mut b) = (w[0], w[1]);
        let (mut fa, mut fb) = (a.p_im_pa - target, b.p_im_pa - target);
        let mut best = if fa.abs() < fb.abs() { a } else { b };
        let mut side = 0i8;
        for _ in 0..60 {
            if (best.p_im_pa - target).abs() <= PRESSURE_TOL * target {
                break;
            }
            let s = if fb != fa {
                (a.s * fb - b.s * fa) / (fb - fa)
            } else {
                0.5 * (a.s + b.s)
            };
            let p = point_at(model, speed, s, c, actuator_path, Some(&best.state)).map_err(err)?;
            let fp = p.p_im_pa - target;
            if fp.abs() < (best.p_im_pa - target).abs() {
                best = p;
            }
            if fp * fb < 0.0 {
                a = b;
                fa = fb;
                b = p;
                fb = fp;
                side = 0;
            } else {
                b = p;
                fb = fp;
                if side == -1 {
                    fa /= 2.0;
                }
                side = -1;
            }
        }
        out.push(Some(best));
    }
    Ok(out)
}

/// State noise (continuous, per second) sampled at one engine-map point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseSample {
    /// The point's engine speed (rad/s).
    pub speed_rad_s: f64,
    /// The point's intake manifold pressure (Pa).
    pub p_im_pa: f64,
    /// Variance of each state (state units squared), diagonal of `Q`.
    pub q: [f64; N_STATES_AUGMENTED],
}

/// The six volumes (m^3, state order) and the air's and exhaust's gas constants (J/(kg K)):
/// what turns a pressure error into a mass error, `dM = dp V / (R T)`.
fn volumes_and_gas_constants(model: &TurboModel) -> ([f64; 6], f64, f64) {
    let p = model.params();
    (
        [
            p.air_filter_volume_m3,
            p.compressor_volume_m3,
            p.intercooler_volume_m3,
            p.intake_manifold_volume_m3,
            p.exhaust_manifold_volume_m3,
            p.exhaust_system_volume_m3,
        ],
        p.air_gas_constant_j_per_kg_k,
        p.exhaust_gas_constant_j_per_kg_k,
    )
}

/// Floors every entry (and replaces a non-finite one) at [`Q_FLOOR_FRACTION`] of its state's
/// scale, squared.
fn apply_q_floor(q: &mut [f64; N_STATES_AUGMENTED], scales: &[f64; N_STATES_AUGMENTED]) {
    for (qi, s) in q.iter_mut().zip(scales) {
        let floor = (Q_FLOOR_FRACTION * s).powi(2);
        if !qi.is_finite() || *qi < floor {
            *qi = floor;
        }
    }
}

/// The paper's state noise at every engine-map point: the squared stationary error of each
/// state (model minus measured, from the whole-model check), a volume's mass error from its
/// pressure error at the measured temperature. Substitutes where the map measures nothing:
/// the compressor-outlet volume takes the intercooler's errors (the map has no sensor between
/// compressor and intercooler); the air filter temperature the intercooler temperature's
/// error; the turbo speed `turbo_speed_error_rad_s` (the map has no turbo speed; the caller
/// measures it where a log has one); `dC_eta_vol` the relative air-flow error times the
/// point's volumetric-efficiency factor (what a constant offset of the factor would have to
/// correct). Everything is floored at [`Q_FLOOR_FRACTION`] of the state scales.
pub fn state_noise_from_map(
    model: &TurboModel,
    points: &[EnginePoint],
    check: &CheckReport,
    turbo_speed_error_rad_s: f64,
) -> Vec<NoiseSample> {
    let (v, r_air, r_exh) = volumes_and_gas_constants(model);
    let scales = model.state_scales();
    let mut out = Vec::with_capacity(check.points.len());
    for pc in &check.points {
        let Some(ep) = points.get(pc.index) else {
            continue;
        };
        // Quantity order of the check: p_af, p_ic, p_im, p_em, p_t, T_ic, T_im, T_em, T_t, W.
        let e: [f64; 10] = std::array::from_fn(|i| pc.model[i] - pc.measured[i]);
        let m = &pc.measured;
        let mass = |dp: f64, vol: f64, r: f64, t: f64| dp * vol / (r * t);
        let mut q = [0.0; N_STATES_AUGMENTED];
        q[X_M_AF] = mass(e[0], v[0], r_air, ep.t_af_k).powi(2);
        q[X_T_AF] = e[5].powi(2);
        q[X_M_C] = mass(e[1], v[1], r_air, m[5]).powi(2);
        q[X_T_C] = e[5].powi(2);
        q[X_M_IC] = mass(e[1], v[2], r_air, m[5]).powi(2);
        q[X_T_IC] = e[5].powi(2);
        q[X_M_IM] = mass(e[2], v[3], r_air, m[6]).powi(2);
        q[X_T_IM] = e[6].powi(2);
        q[X_M_EM] = mass(e[3], v[4], r_exh, m[7]).powi(2);
        q[X_T_EM] = e[7].powi(2);
        q[X_M_ES] = mass(e[4], v[5], r_exh, m[8]).powi(2);
        q[X_T_ES] = e[8].powi(2);
        q[X_OMEGA_T] = turbo_speed_error_rad_s.powi(2);
        let rel_w = if pc.model[9].abs() > 0.0 {
            e[9] / pc.model[9]
        } else {
            0.0
        };
        let x = model.state_from_pressures(
            [m[0], m[1], m[1], m[2], m[3], m[4]],
            [ep.t_af_k, m[5], m[5], m[6], m[7], m[8]],
            pc.turbo_speed_rad_s,
        );
        let u = crate::models::turbo::fit::check::input(ep, pc.wastegate, ep.p_af_pa);
        let factor = model.signals(&x, &u).eta_vol_factor;
        q[X_DC_ETA_VOL] = (rel_w * factor).powi(2);
        apply_q_floor(&mut q, scales);
        out.push(NoiseSample {
            speed_rad_s: ep.engine_speed_rev_s * std::f64::consts::TAU,
            p_im_pa: ep.p_im_pa,
            q,
        });
    }
    out
}

/// Relative error taken for the exhaust temperatures where no exhaust temperature is measured
/// (the LiU-ICE logs): 10 %, between the TSFS09 fit's stationary RMS errors of `T_em` (6.3 %) and
/// `T_t` (12 %) on the one engine whose map measures them; the LiU-ICE set keeps VEP4's exhaust
/// parameters, never checked against its engine, so no smaller error can be claimed.
pub const UNMEASURED_EXHAUST_TEMP_REL: f64 = 0.10;
/// The paper's state noise from a driving log instead of an engine map, for an engine that has
/// none (the LiU-ICE engine): at each quasi-stationary sample of the log
/// ([`crate::models::turbo::fit::ice::quasi_stationary`], the samples `fdd fit turbo-ice`
/// judges the model on), the model's stationary point at the sample's inputs against the
/// measured `p_ic`, `T_ic`, `p_im` and air flow, each squared error mapped to the states as
/// [`state_noise_from_map`] maps the map's: a volume's mass error from its pressure error at
/// the model's temperature.
///
/// The log measures fewer quantities than a map; the substitutes, each from what the log does
/// measure:
/// - air filter pressure (`m_af`): the relative flow error `e_W` through the air filter's
///   (quadratic) restriction, `dp_af = 2 e_W (p_amb - p_af)`;
/// - compressor outlet (`m_c`, `T_c`): the intercooler's errors, as for the map;
/// - air filter and manifold temperatures (`T_af`, `T_im`): the `T_ic` error (the fit takes
///   `T_ic` for the manifold temperature);
/// - exhaust manifold and system pressures (`m_em`, `m_es`): the flow error through the
///   restrictions behind them, `dp = 2 e_W (p - p_amb)`;
/// - exhaust temperatures: [`UNMEASURED_EXHAUST_TEMP_REL`] of the model's;
/// - turbo speed: `turbo_speed_error_rad_s`, as for the map: the caller's (the log has no
///   turbo speed);
/// - `dC_eta_vol`: `e_W` times the point's volumetric-efficiency factor, as for the map.
///
/// Floored at [`Q_FLOOR_FRACTION`] of the state scales. A sample whose stationary point the
/// model does not find (from the previous sample's nor from the default start) is skipped;
/// the count of samples used is the length of the result.
pub fn state_noise_from_log(
    model: &TurboModel,
    samples: &[crate::models::turbo::fit::ice::LogSample],
    opts: &crate::models::turbo::fit::ice::IceOptions,
    turbo_speed_error_rad_s: f64,
) -> Vec<NoiseSample> {
    let mask = crate::models::turbo::fit::ice::quasi_stationary(samples, opts);
    let (v, r_air, r_exh) = volumes_and_gas_constants(model);
    let scales = model.state_scales();
    let mut out = Vec::new();
    let mut guess: Option<TurboState> = None;
    for (s, _) in samples.iter().zip(&mask).filter(|(_, m)| **m) {
        let u = TurboInput {
            throttle_pct: s.throttle_pct,
            engine_speed_rad_s: s.engine_speed_rad_s,
            wastegate_frac: s.wastegate,
            lambda: opts.lambda,
            ambient_pressure_pa: s.ambient_pressure_pa,
            ambient_temperature_k: s.ambient_temperature_k,
        };
        let st = model
            .stationary_point(&u, guess.as_ref())
            .or_else(|_| model.stationary_point(&u, None));
        let Ok(st) = st else {
            continue;
        };
        guess = Some(st.state);
        let m = model.signals(&st.state, &u);
        let e_pic = m.p_ic_pa - s.p_ic_pa;
        let e_pim = m.p_im_pa - s.p_im_pa;
        let e_tic = m.t_ic_k - s.t_ic_k;
        let e_w = if s.air_flow_kg_s > 0.0 {
            (m.w_af_kg_s - s.air_flow_kg_s) / s.air_flow_kg_s
        } else {
            0.0
        };
        let amb = s.ambient_pressure_pa;
        let mass = |dp: f64, vol: f64, r: f64, t: f64| dp * vol / (r * t);
        let mut q = [0.0; N_STATES_AUGMENTED];
        q[X_M_AF] = mass(2.0 * e_w * (amb - m.p_af_pa), v[0], r_air, m.t_af_k).powi(2);
        q[X_T_AF] = e_tic.powi(2);
        q[X_M_C] = mass(e_pic, v[1], r_air, m.t_c_k).powi(2);
        q[X_T_C] = e_tic.powi(2);
        q[X_M_IC] = mass(e_pic, v[2], r_air, m.t_ic_k).powi(2);
        q[X_T_IC] = e_tic.powi(2);
        q[X_M_IM] = mass(e_pim, v[3], r_air, m.t_im_k).powi(2);
        q[X_T_IM] = e_tic.powi(2);
        q[X_M_EM] = mass(2.0 * e_w * (m.p_em_pa - amb), v[4], r_exh, m.t_em_k).powi(2);
        q[X_T_EM] = (UNMEASURED_EXHAUST_TEMP_REL * m.t_em_k).powi(2);
        q[X_M_ES] = mass(2.0 * e_w * (m.p_es_pa - amb), v[5], r_exh, m.t_es_k).powi(2);
        q[X_T_ES] = (UNMEASURED_EXHAUST_TEMP_REL * m.t_es_k).powi(2);
        q[X_OMEGA_T] = turbo_speed_error_rad_s.powi(2);
        q[X_DC_ETA_VOL] = (e_w * m.eta_vol_factor).powi(2);
        apply_q_floor(&mut q, scales);
        out.push(NoiseSample {
            speed_rad_s: s.engine_speed_rad_s,
            p_im_pa: s.p_im_pa,
            q,
        });
    }
    out
}

/// The state noise at (speed, pressure): the mean of the [`NEAREST_MAP_POINTS`] samples nearest
/// in coordinates normalized by the samples' ranges. `None` without samples.
pub fn state_noise_at(
    samples: &[NoiseSample],
    speed_rad_s: f64,
    p_im_pa: f64,
) -> Option<[f64; N_STATES_AUGMENTED]> {
    if samples.is_empty() {
        return None;
    }
    let range = |f: fn(&NoiseSample) -> f64| {
        let lo = samples.iter().map(f).fold(f64::INFINITY, f64::min);
        let hi = samples.iter().map(f).fold(f64::NEG_INFINITY, f64::max);
        (hi - lo).max(f64::MIN_POSITIVE)
    };
    let rs = range(|s| s.speed_rad_s);
    let rp = range(|s| s.p_im_pa);
    let mut d: Vec<(f64, usize)> = samples
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let a = (s.speed_rad_s - speed_rad_s) / rs;
            let b = (s.p_im_pa - p_im_pa) / rp;
            (a * a + b * b, i)
        })
        .collect();
    d.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    let k = NEAREST_MAP_POINTS.min(d.len());
    let mut q = [0.0; N_STATES_AUGMENTED];
    for &(_, i) in &d[..k] {
        for (qj, sj) in q.iter_mut().zip(samples[i].q.iter()) {
            *qj += sj / k as f64;
        }
    }
    Some(q)
}

/// What a design needs besides the model and the state noise.
#[derive(Debug, Clone, PartialEq)]
pub struct DesignOptions<const M: usize> {
    /// Sample time (s).
    pub dt_s: f64,
    /// The sensors, in the order of the gains' columns.
    pub sensors: [Sensor; M],
    /// Measurement noise: variance of each sensor about its stationary mean (sensor units
    /// squared).
    pub r: [f64; M],
    /// Speed nodes (rad/s), increasing.
    pub speeds_rad_s: Vec<f64>,
    /// Pressure nodes (Pa), increasing.
    pub pressures_pa: Vec<f64>,
    /// Ambient and mixture.
    pub conditions: Conditions,
}

/// One node of a design.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeReport {
    /// Speed (rad/s).
    pub speed_rad_s: f64,
    /// Pressure (Pa).
    pub pressure_pa: f64,
    /// The operating point, if the node is reachable.
    pub point: Option<OperatingPoint>,
    /// The operating point the gain was designed at: the node's own, or for an unreachable
    /// node the nearest reachable one's at the same speed.
    pub design_point: OperatingPoint,
    /// Spectral radius of the discrete closed loop `(I - K C) Phi` (below 1: stable).
    pub closed_loop_radius: f64,
}

/// The gain table and what each node was.
#[derive(Debug, Clone)]
pub struct Design<const M: usize> {
    /// The table.
    pub table: GainTable<M>,
    /// Per node, speed-major.
    pub nodes: Vec<NodeReport>,
}

/// The stationary Kalman gain of the model linearized at `x` (augmented, `dC_eta_vol` = 0)
/// with input `u`, and the closed loop's spectral radius.
pub fn node_gain<const M: usize>(
    step: &TurboDiscrete14,
    sensors: &[Sensor; M],
    x: &TurboState,
    u: &TurboInput,
    q: &[f64; N_STATES_AUGMENTED],
    r: &[f64; M],
) -> Result<(SMatrix<f64, N_STATES_AUGMENTED, M>, f64), DareErrorOrModel> {
    let mut xa = TurboStateAugmented::zeros();
    for i in 0..N_STATES {
        xa[i] = x[i];
    }
    let (_, phi) = step
        .step_with_jacobian(&xa, u)
        .map_err(DareErrorOrModel::Model)?;
    let (_, c) = measurement(step.model(), sensors, &xa, u);
    let dt = step.dt_s();
    let qd = SMatrix::<f64, N_STATES_AUGMENTED, N_STATES_AUGMENTED>::from_diagonal(
        &nalgebra::SVector::from_fn(|i, _| q[i] * dt),
    );
    let rd = SMatrix::<f64, M, M>::from_diagonal(&nalgebra::SVector::from_fn(|i, _| r[i] / dt));
    let kf = stationary_kalman(&phi, &c, &qd, &rd).map_err(DareErrorOrModel::Dare)?;
    let id = SMatrix::<f64, N_STATES_AUGMENTED, N_STATES_AUGMENTED>::identity();
    let radius = crate::dare::spectral_radius(&((id - kf.filter_gain * c) * phi));
    Ok((kf.filter_gain, radius))
}

/// Either failure of [`node_gain`].
#[derive(Debug, Clone, PartialEq)]
pub enum DareErrorOrModel {
    /// The step failed.
    Model(TurboError),
    /// The Riccati equation failed.
    Dare(DareError),
}

/// Designs the gain table (see the module docs) on the default actuator path.
pub fn design_gains<const M: usize>(
    model: &TurboModel,
    opts: &DesignOptions<M>,
    noise: &[NoiseSample],
) -> Result<Design<M>, DesignError> {
    design_gains_on_path(model, opts, noise, &ActuatorPath::default())
}

/// Designs the gain table (see the module docs) with the operating points on `path`.
pub fn design_gains_on_path<const M: usize>(
    model: &TurboModel,
    opts: &DesignOptions<M>,
    noise: &[NoiseSample],
    path: &ActuatorPath,
) -> Result<Design<M>, DesignError> {
    if noise.is_empty() {
        return Err(DesignError::NoNoise);
    }
    let step = TurboDiscrete14::new(model.clone(), opts.dt_s, opts.dt_s)?;
    let np = opts.pressures_pa.len();
    let mut gains = Vec::with_capacity(opts.speeds_rad_s.len() * np);
    let mut nodes = Vec::with_capacity(opts.speeds_rad_s.len() * np);
    for &speed in &opts.speeds_rad_s {
        let points = operating_points(model, speed, &opts.pressures_pa, &opts.conditions, path)?;
        let feasible: Vec<usize> = (0..np).filter(|&j| points[j].is_some()).collect();
        if feasible.is_empty() {
            return Err(DesignError::Unreachable {
                speed_rad_s: speed,
                lo_pa: f64::NAN,
                hi_pa: f64::NAN,
            });
        }
        for (j, &pressure) in opts.pressures_pa.iter().enumerate() {
            // An unreachable node takes the nearest reachable one's operating point.
            let src = *feasible
                .iter()
                .min_by_key(|&&f| f.abs_diff(j))
                .unwrap_or(&feasible[0]);
            let Some(op) = points[src] else {
                continue;
            };
            let q = state_noise_at(noise, speed, op.p_im_pa).ok_or(DesignError::NoNoise)?;
            let (k, radius) = node_gain(&step, &opts.sensors, &op.state, &op.input, &q, &opts.r)
                .map_err(|e| match e {
                    DareErrorOrModel::Model(source) => DesignError::Model {
                        speed_rad_s: speed,
                        source,
                    },
                    DareErrorOrModel::Dare(source) => DesignError::Dare {
                        speed_rad_s: speed,
                        pressure_pa: pressure,
                        source,
                    },
                })?;
            gains.push(k);
            nodes.push(NodeReport {
                speed_rad_s: speed,
                pressure_pa: pressure,
                point: points[j],
                design_point: op,
                closed_loop_radius: radius,
            });
        }
    }
    let table = GainTable::new(opts.speeds_rad_s.clone(), opts.pressures_pa.clone(), gains)?;
    Ok(Design { table, nodes })
}
