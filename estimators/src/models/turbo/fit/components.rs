//! The component fits, in the order they depend on each other, and [`fit_turbo`], which runs
//! them all from a start parameter set.
//!
//! | component | form (the model's) | data | fitted |
//! |---|---|---|---|
//! | air filter | restriction from ambient to `p_af` | `p_af`, `T_af`, air flow | ambient pressure, `H` |
//! | exhaust system | restriction from `p_t` to ambient | `p_t`, `T_t`, air + fuel flow | `H` |
//! | volumetric efficiency | `poly4(p_im) (r_c - (p_em/p_im)^(1/k_e))/(r_c - 1) p_im V_d w_e/(4 pi R T)` | `p_im`, `p_em`, `T_bef_thr`, N, air flow | 5 coefficients (`C_eta_vol` 1) |
//! | throttle | `A(th) = a0 + a1 th + a2 th^2` in the `k_th` flow function | `p_bef_thr`, `T_bef_thr`, `p_im`, alpha, air flow | `a0, a1, a2` |
//! | exhaust temperature | `T_0 + C_eo W_eo`, pipe heat loss | `T_em`, `T_af`, air + fuel flow | `T_0`, `C_eo`, pipe length |
//! | compressor | Psi-Phi ellipse, efficiency parabola in Phi | compressor map | `Psi_max`, `Phi_max`, `eta_max`, `Phi_opt` |
//! | intercooler | outlet `T_c - eps (T_c - T_amb)` | `T_bef_thr`, the compressor model's `T_c` | `eps` |
//! | turbine flow | `k1 p_em / sqrt(T_em) sqrt(1 - Pi_t^k2)` | `p_em`, `p_t`, `T_em`, air + fuel flow where the wastegate is taken as closed | `k1`, `k2` |
//! | turbine efficiency | parabola in the blade speed ratio | the power the compressor model needs at the same points | `eta_max`, `BSR_opt` |
//!
//! Decisions (each explained at its function): the ambient pressure is one constant for the
//! whole map, fitted with the air filter; the ambient temperature is each point's `T_af`; the
//! volumetric efficiency is fitted with the throttle-inlet temperature, which is the manifold
//! temperature of the model (adiabatic throttle and manifold); the wastegate is taken as closed
//! at points with a boost ratio of at least [`FitOptions::closed_wastegate_boost_ratio`]; the
//! turbine map is fitted too but only reported (its flow parameter is 4 to 5 times below the
//! engine's measured exhaust flow at the same expansion ratio).

use std::f64::consts::PI;

use nalgebra::{DMatrix, DVector};

use super::super::compressor::Compressor;
use super::super::dynamics::Consts;
use super::super::restriction::Restriction;
use super::super::TurboParams;
use super::least_squares::{levenberg_marquardt, linear_least_squares, LmOptions, LmSolution};
use super::{
    rms, with_constants, CompressorMapPoint, EnginePoint, FitData, FitError, FitOptions,
    TurbineMapPoint,
};

/// A fitted value with its standard error from the least-squares fit (NaN for a value that is
/// computed rather than fitted by least squares, or from a singular fit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// The value.
    pub value: f64,
    /// Its standard error.
    pub std_error: f64,
}

/// The air filter fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AirFilterFit {
    /// Ambient pressure (Pa), one for the whole map.
    pub ambient_pressure_pa: Estimate,
    /// Resistance `H` (Pa^2 s^2 / (kg^2 K)).
    pub resistance: Estimate,
    /// RMS of the `p_af` residual (Pa).
    pub rms_pa: f64,
    /// Points used.
    pub points: usize,
}

/// The exhaust-system restriction fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExhaustFit {
    /// Resistance `H` (Pa^2 s^2 / (kg^2 K)).
    pub resistance: Estimate,
    /// RMS of the `p_t` residual (Pa).
    pub rms_pa: f64,
    /// Points used.
    pub points: usize,
}

/// The volumetric-efficiency fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolEffFit {
    /// Polynomial in `p_im` (kPa), highest power first (`C_eta_vol` = 1).
    pub poly_kpa: [f64; 5],
    /// Argument range (kPa): the training points' `p_im` range, rounded outwards.
    pub min_kpa: f64,
    /// Upper end (kPa).
    pub max_kpa: f64,
    /// RMS of the air-flow residual (kg/s).
    pub rms_kg_s: f64,
    /// RMS of the relative air-flow residual (-).
    pub rms_rel: f64,
    /// Points used.
    pub points: usize,
}

/// The throttle area fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThrottleFit {
    /// `[a0, a1, a2]` (m^2, m^2/rad, m^2/rad^2).
    pub coeffs: [f64; 3],
    /// RMS of the relative flow (= area) residual at the points used (-).
    pub rms_rel: f64,
    /// Points used (those where the throttle restricts: `p_im / p_bef_thr` below
    /// [`THROTTLE_MAX_RATIO`]).
    pub points: usize,
}

/// The exhaust temperature fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExhaustTempFit {
    /// `T_0` (K).
    pub t0_k: Estimate,
    /// `C_eo` (K s/kg).
    pub c_eo: Estimate,
    /// Pipe length (m): the heat-loss area's free factor.
    pub pipe_length_m: Estimate,
    /// RMS of the `T_em` residual (K).
    pub rms_k: f64,
    /// Points used.
    pub points: usize,
}

/// The compressor map fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompressorFit {
    /// `Psi_max` (-).
    pub head_max: Estimate,
    /// `Phi_max` (-).
    pub flow_max: Estimate,
    /// RMS of the flow-parameter residual (-).
    pub rms_phi: f64,
    /// Peak efficiency (-).
    pub efficiency_max: Estimate,
    /// Flow parameter at the peak (-).
    pub flow_at_efficiency_max: Estimate,
    /// RMS of the efficiency residual (-).
    pub rms_eta: f64,
    /// Points used.
    pub points: usize,
}

/// The intercooler fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntercoolerFit {
    /// Effectiveness (-).
    pub effectiveness: f64,
    /// RMS of the `T_bef_thr` residual (K).
    pub rms_k: f64,
    /// Points used (those where the compressor model has a solution).
    pub points: usize,
}

/// The turbine fits from the engine map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurbineFit {
    /// `k1` (kg K^0.5 / (s kPa)).
    pub k1: Estimate,
    /// RMS of the relative flow residual (-).
    pub rms_flow_rel: f64,
    /// Peak efficiency (-).
    pub efficiency_max: Estimate,
    /// The blade speed ratios of the points (min, max) (-): too narrow a range to place the
    /// parabola's peak, which stays at the start file's.
    pub bsr_range: (f64, f64),
    /// RMS of the relative turbine-torque residual (-).
    pub rms_torque_rel: f64,
    /// Points used (boost ratio at least the closed-wastegate threshold).
    pub points: usize,
    /// At the training points below the threshold: the mean share of the exhaust flow the
    /// fitted turbine does not pass at the measured pressures (-), i.e. what a wastegate
    /// would have to pass there.
    pub unboosted_bypass_share: f64,
    /// Those points.
    pub unboosted_points: usize,
}

/// The turbine map, fitted with the same forms but only reported.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurbineMapFit {
    /// `k1` of the map's flow parameter (kg K^0.5 / (s kPa)).
    pub k1: f64,
    /// `k2` (-).
    pub k2: f64,
    /// Peak efficiency of the map (-).
    pub efficiency_max: f64,
    /// Its blade speed ratio with the model's turbine diameter (-).
    pub bsr_at_efficiency_max: f64,
    /// Median of (engine-map exhaust flow parameter / map flow parameter at the same
    /// expansion ratio) over the boosted training points (-).
    pub engine_to_map_flow_ratio: f64,
    /// Points.
    pub points: usize,
}

/// Every fit's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitReport {
    /// Air filter and the ambient pressure.
    pub air_filter: AirFilterFit,
    /// Exhaust system.
    pub exhaust: ExhaustFit,
    /// Volumetric efficiency.
    pub vol_eff: VolEffFit,
    /// Throttle.
    pub throttle: ThrottleFit,
    /// Exhaust temperature and pipe heat loss.
    pub exhaust_temp: ExhaustTempFit,
    /// Compressor.
    pub compressor: CompressorFit,
    /// Intercooler.
    pub intercooler: IntercoolerFit,
    /// Turbine from the engine map.
    pub turbine: TurbineFit,
    /// Turbine map (reported, not used).
    pub turbine_map: TurbineMapFit,
    /// Engine-map points used for the component fits (not held out).
    pub training_points: usize,
    /// Points held out.
    pub held_out_points: usize,
}

/// The fitted parameter set, its report and the ambient pressure the whole-model check uses.
#[derive(Debug, Clone, PartialEq)]
pub struct FitOutcome {
    /// The calibrated parameters (validated).
    pub params: TurboParams,
    /// What each fit found.
    pub report: FitReport,
}

/// Pressure ratio `p_im / p_bef_thr` above which a point does not determine the throttle area:
/// the flow function's value there is a small difference of two nearly equal pressures, so a
/// sensor offset of a few hundred pascals changes the area computed from it by tens of percent.
pub const THROTTLE_MAX_RATIO: f64 = 0.95;

/// Bisection steps for the restriction and compressor inversions (interval / 2^100: exact to
/// the last bit, and a fixed count keeps the result deterministic).
const BISECTION_STEPS: usize = 100;

fn estimate(s: &LmSolution, j: usize, scale: f64) -> Estimate {
    Estimate {
        value: s.x[j] * scale,
        std_error: s.std_errors[j] * scale,
    }
}

/// Estimate of a parameter fitted as `exp(x_j) * scale` (std error by the delta method).
fn estimate_exp(s: &LmSolution, j: usize, scale: f64) -> Estimate {
    let value = s.x[j].exp() * scale;
    Estimate {
        value,
        std_error: s.std_errors[j] * value,
    }
}

fn solved(s: Option<LmSolution>, what: &'static str) -> Result<LmSolution, FitError> {
    s.ok_or(FitError::Solver {
        what,
        reason: "residuals not finite at the start values",
    })
}

fn need(what: &'static str, got: usize, n: usize) -> Result<(), FitError> {
    if got < n {
        Err(FitError::TooFewPoints { what, got, need: n })
    } else {
        Ok(())
    }
}

/// Exhaust flow of a point (kg/s): the measured air plus the fuel at the measured lambda.
pub fn exhaust_flow(p: &EnginePoint, afs: f64) -> f64 {
    p.air_flow_kg_s * (1.0 + 1.0 / (afs * p.lambda))
}

/// Engine speed (rad/s) of a point.
pub fn engine_speed_rad_s(p: &EnginePoint) -> f64 {
    p.engine_speed_rev_s * 2.0 * PI
}

/// The downstream pressure (Pa) at which restriction `r` passes `w` (kg/s, forward) from
/// `(p_us, t_us)`: bisection on the model's own flow function. `None` if even a vacuum
/// downstream would not pass `w`.
pub fn downstream_pressure(r: &Restriction, p_us: f64, t_us: f64, w: f64) -> Option<f64> {
    let flow = |p_ds: f64| r.flow(p_us, t_us, p_ds, t_us).0;
    if !(flow(0.0) >= w) {
        return None;
    }
    let (mut lo, mut hi) = (0.0, p_us);
    for _ in 0..BISECTION_STEPS {
        let mid = 0.5 * (lo + hi);
        if flow(mid) > w {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}

/// The upstream pressure (Pa) at which restriction `r` passes `w` (kg/s, forward) at
/// temperature `t_us` into `p_ds`: bisection on the model's flow function up to 10 times
/// `p_ds`. `None` if not even that passes `w`.
pub fn upstream_pressure(r: &Restriction, p_ds: f64, t_us: f64, w: f64) -> Option<f64> {
    let flow = |p_us: f64| r.flow(p_us, t_us, p_ds, t_us).0;
    let top = 10.0 * p_ds;
    if !(flow(top) >= w) {
        return None;
    }
    let (mut lo, mut hi) = (p_ds, top);
    for _ in 0..BISECTION_STEPS {
        let mid = 0.5 * (lo + hi);
        if flow(mid) < w {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(0.5 * (lo + hi))
}

/// Air filter and ambient pressure: `p_af = p_amb - dp(W)` through the model's restriction with
/// the upstream at `(p_amb, T_af)`. The map has no ambient pressure column, and the barometer
/// was not logged; the lowest-flow points (`p_af` 101.2-101.6 kPa at under 10 g/s) show it was
/// about 101.3 kPa and varied by a few hundred pascals between sessions. One constant is fitted
/// together with `H` (two parameters, Levenberg-Marquardt on the `p_af` residual in Pa): the
/// air filter's drop is what separates them (up to 14 kPa at 156 g/s).
pub fn fit_air_filter(
    points: &[EnginePoint],
    start: &TurboParams,
) -> Result<AirFilterFit, FitError> {
    need("air filter", points.len(), 3)?;
    let dp_lin = start.air_filter_linear_dp_pa;
    let predict = |x: &[f64], p: &EnginePoint| {
        let r = Restriction {
            h: x[1].exp() * 1e8,
            dp_lin,
        };
        downstream_pressure(&r, x[0] * 1e5, p.t_af_k, p.air_flow_kg_s)
    };
    let residuals = |x: &[f64]| {
        points
            .iter()
            .map(|p| predict(x, p).map(|v| v - p.p_af_pa))
            .collect::<Option<Vec<f64>>>()
    };
    let p0 = points.iter().map(|p| p.p_af_pa).fold(0.0, f64::max) / 1e5;
    let x0 = [
        p0,
        (start.air_filter_resistance_pa2_s2_per_kg2_k / 1e8).ln(),
    ];
    let s = solved(
        levenberg_marquardt(residuals, &x0, &[1.0, 1.0], &LmOptions::default()),
        "air filter",
    )?;
    Ok(AirFilterFit {
        ambient_pressure_pa: estimate(&s, 0, 1e5),
        resistance: estimate_exp(&s, 1, 1e8),
        rms_pa: s.residual_rms,
        points: points.len(),
    })
}

/// Exhaust system: `p_t` upstream of the model's restriction into the ambient pressure, passing
/// the exhaust flow (air plus fuel) at the measured `T_t`. One parameter, `H`.
pub fn fit_exhaust(
    points: &[EnginePoint],
    start: &TurboParams,
    p_amb: f64,
) -> Result<ExhaustFit, FitError> {
    need("exhaust system", points.len(), 2)?;
    let afs = start.stoichiometric_air_fuel_ratio;
    let dp_lin = start.exhaust_linear_dp_pa;
    let residuals = |x: &[f64]| {
        let r = Restriction {
            h: x[0].exp() * 1e8,
            dp_lin,
        };
        points
            .iter()
            .map(|p| {
                upstream_pressure(&r, p_amb, p.t_t_k, exhaust_flow(p, afs)).map(|v| v - p.p_t_pa)
            })
            .collect::<Option<Vec<f64>>>()
    };
    let x0 = [(start.exhaust_resistance_pa2_s2_per_kg2_k / 1e8).ln()];
    let s = solved(
        levenberg_marquardt(residuals, &x0, &[1.0], &LmOptions::default()),
        "exhaust system",
    )?;
    Ok(ExhaustFit {
        resistance: estimate_exp(&s, 0, 1e8),
        rms_pa: s.residual_rms,
        points: points.len(),
    })
}

/// Volumetric efficiency: the model's cylinder flow with the polynomial as the whole factor
/// (`C_eta_vol` 1), which is linear in its five coefficients, fitted by linear least squares on
/// the air flow in kg/s (so the high-flow points, where the air flow and the manifold pressure
/// are largest, weigh as the whole-model RMSE figures weigh them). The temperature is the
/// measured throttle-inlet temperature `T_bef_thr`, not `T_im`: the model's throttle and
/// manifold are adiabatic, so its `T_im` is its intercooler temperature, while the measured
/// manifold is up to 15 K warmer than the throttle inlet at low load (heated by the engine); a
/// fit on `T_im` would make the whole model's flow that much too high there. The model's
/// factor depends on `p_im` only; the data also vary with engine speed (the fitted factor's
/// residual is about 4 % RMS, largest at 4300 rpm and low load), which no choice of these five
/// coefficients can follow.
pub fn fit_vol_eff(points: &[EnginePoint], start: &TurboParams) -> Result<VolEffFit, FitError> {
    need("volumetric efficiency", points.len(), 6)?;
    let lo = points
        .iter()
        .map(|p| p.p_im_pa / 1000.0)
        .fold(f64::INFINITY, f64::min)
        .floor();
    let hi = points
        .iter()
        .map(|p| p.p_im_pa / 1000.0)
        .fold(f64::NEG_INFINITY, f64::max)
        .ceil();
    let mut base = start.clone();
    base.vol_eff_factor = 1.0;
    base.vol_eff_poly_kpa = [0.0, 0.0, 0.0, 0.0, 1.0];
    base.vol_eff_poly_min_kpa = lo;
    base.vol_eff_poly_max_kpa = hi;
    let cyl = Consts::new(&base).cylinders;
    let flows: Vec<f64> = points
        .iter()
        .map(|p| {
            cyl.point(
                p.p_im_pa,
                p.t_ic_k,
                p.p_em_pa,
                engine_speed_rad_s(p),
                p.lambda,
                p.t_af_k,
                0.0,
            )
            .w_ei
        })
        .collect();
    let a = DMatrix::from_fn(points.len(), 5, |i, j| {
        let x = (points[i].p_im_pa / 1000.0).clamp(lo, hi);
        flows[i] * x.powi(4 - j as i32)
    });
    let b = DVector::from_iterator(points.len(), points.iter().map(|p| p.air_flow_kg_s));
    let c = linear_least_squares(&a, &b).ok_or(FitError::Solver {
        what: "volumetric efficiency",
        reason: "singular",
    })?;
    let fitted = &a * &c;
    let poly_kpa = [c[0], c[1], c[2], c[3], c[4]];
    Ok(VolEffFit {
        poly_kpa,
        min_kpa: lo,
        max_kpa: hi,
        rms_kg_s: rms(fitted.iter().zip(b.iter()).map(|(f, m)| f - m)),
        rms_rel: rms(fitted.iter().zip(b.iter()).map(|(f, m)| (f - m) / m)),
        points: points.len(),
    })
}

/// Throttle: the effective area each point implies, `W / (flow per unit area)` with the
/// model's flow function (its `k_th` and linear continuation) at the measured
/// `p_bef_thr, T_bef_thr, p_im`, fitted by the quadratic in the plate angle (the start file's
/// angle map, `th = gain alpha + offset`) with relative weights (each point's flow error in
/// percent counts alike, from 3 to 150 g/s). Points where the throttle hardly restricts
/// (`p_im / p_bef_thr` at or above [`THROTTLE_MAX_RATIO`]) are left out: they do not
/// determine the area.
pub fn fit_throttle(points: &[EnginePoint], start: &TurboParams) -> Result<ThrottleFit, FitError> {
    let c = Consts::new(start);
    let rows: Vec<(f64, f64)> = points
        .iter()
        .filter(|p| p.p_im_pa / p.p_ic_pa < THROTTLE_MAX_RATIO)
        .map(|p| {
            let per_area = c
                .throttle
                .nozzle
                .flow(1.0, p.p_ic_pa, p.t_ic_k, p.p_im_pa, p.t_im_k)
                .0;
            let th = (start.throttle_angle_gain_deg_per_pct * p.throttle_frac * 100.0
                + start.throttle_angle_offset_deg)
                * PI
                / 180.0;
            (th, p.air_flow_kg_s / per_area)
        })
        .filter(|(_, a)| a.is_finite() && *a > 0.0)
        .collect();
    need("throttle", rows.len(), 4)?;
    let a = DMatrix::from_fn(rows.len(), 3, |i, j| rows[i].0.powi(j as i32) / rows[i].1);
    let b = DVector::from_element(rows.len(), 1.0);
    let x = linear_least_squares(&a, &b).ok_or(FitError::Solver {
        what: "throttle",
        reason: "singular",
    })?;
    let fitted = &a * &x;
    Ok(ThrottleFit {
        coeffs: [x[0], x[1], x[2]],
        rms_rel: rms(fitted.iter().map(|f| f - 1.0)),
        points: rows.len(),
    })
}

/// Exhaust temperature: the model's `T_em,in` (engine-out `T_0 + C_eo W_eo`, then the pipe heat
/// loss towards `T_af`) at the measured exhaust flow, against the measured `T_em`; three
/// parameters by Levenberg-Marquardt: `T_0`, `C_eo` and the pipe length, the free factor of the
/// heat-loss exponent (the diameter, count, `h_ext` and gas properties stay at the start file's:
/// with the length they are not separately determined by a temperature). The cylinder code is
/// the model's own, with its volumetric-efficiency factor set per point so that its air flow is
/// the measured one.
pub fn fit_exhaust_temp(
    points: &[EnginePoint],
    start: &TurboParams,
) -> Result<ExhaustTempFit, FitError> {
    need("exhaust temperature", points.len(), 4)?;
    let mut base = start.clone();
    base.vol_eff_factor = 1.0;
    base.vol_eff_poly_kpa = [0.0, 0.0, 0.0, 0.0, 1.0];
    let predict = |x: &[f64], p: &EnginePoint| {
        let mut q = base.clone();
        q.exhaust_temp_zero_flow_k = x[0] * 1000.0;
        q.exhaust_temp_flow_gain_k_s_per_kg = x[1] * 1000.0;
        q.exhaust_pipe_length_m = x[2].exp();
        let mut cyl = Consts::new(&q).cylinders;
        let args = (
            p.p_im_pa,
            p.t_ic_k,
            p.p_em_pa,
            engine_speed_rad_s(p),
            p.lambda,
            p.t_af_k,
        );
        let unit = cyl
            .point(args.0, args.1, args.2, args.3, args.4, args.5, 0.0)
            .w_ei;
        if !(unit > 0.0) {
            return None;
        }
        cyl.c_eta_vol = p.air_flow_kg_s / unit;
        Some(
            cyl.point(args.0, args.1, args.2, args.3, args.4, args.5, 0.0)
                .t_em_in,
        )
    };
    let residuals = |x: &[f64]| {
        points
            .iter()
            .map(|p| predict(x, p).map(|t| t - p.t_em_k))
            .collect::<Option<Vec<f64>>>()
    };
    let x0 = [
        start.exhaust_temp_zero_flow_k / 1000.0,
        start.exhaust_temp_flow_gain_k_s_per_kg / 1000.0,
        start.exhaust_pipe_length_m.ln(),
    ];
    let s = solved(
        levenberg_marquardt(residuals, &x0, &[1.0; 3], &LmOptions::default()),
        "exhaust temperature",
    )?;
    Ok(ExhaustTempFit {
        t0_k: estimate(&s, 0, 1000.0),
        c_eo: estimate(&s, 1, 1000.0),
        pipe_length_m: estimate_exp(&s, 2, 1.0),
        rms_k: s.residual_rms,
        points: points.len(),
    })
}

/// A compressor map point as the model's `(Psi, Phi)` with wheel diameter `d_c` (m): the
/// corrected quantities are the real ones at the reference inlet `(T_ref, p_ref)`, where
/// `U = N 2 pi / 60 D_c / 2`, `Psi = 2 cp T_ref (Pi^((k-1)/k) - 1) / U^2`,
/// `Phi = W / (rho_ref pi D_c^2 / 4 U)`.
pub fn compressor_map_point(
    m: &CompressorMapPoint,
    c: &Compressor,
    t_ref: f64,
    p_ref: f64,
) -> (f64, f64) {
    let u = m.corrected_speed_rpm * 2.0 * PI / 60.0 * c.radius;
    let psi = 2.0 * c.cp * t_ref * (m.pressure_ratio.powf(c.expo) - 1.0) / (u * u);
    let rho = p_ref / (c.r * t_ref);
    let phi = m.corrected_flow_kg_s / (rho * c.area * u);
    (psi, phi)
}

/// Compressor: the ellipse `(Psi_max, Phi_max)` by Levenberg-Marquardt on the flow-parameter
/// residual through the model's own `phi(Psi)` (with its linear continuation near `Psi_max`),
/// then the efficiency parabola `(eta_max, Phi_opt)` on the efficiency residual at the map's
/// `Phi`. The wheel diameter is not determined by a map in corrected quantities (a diameter
/// scales `Psi` by `D^-2` and `Phi` by `D^-3`, and the fitted maxima follow): it stays at the
/// start file's value, and the fitted `Psi_max, Phi_max, Phi_opt` go with it.
pub fn fit_compressor(
    map: &[CompressorMapPoint],
    start: &TurboParams,
    opts: &FitOptions,
) -> Result<CompressorFit, FitError> {
    need("compressor map", map.len(), 4)?;
    let c0 = Consts::new(start).compressor;
    let pts: Vec<(f64, f64, f64)> = map
        .iter()
        .map(|m| {
            let (psi, phi) = compressor_map_point(
                m,
                &c0,
                opts.compressor_reference_temperature_k,
                opts.compressor_reference_pressure_pa,
            );
            (psi, phi, m.efficiency)
        })
        .collect();
    let make = |x: &[f64]| {
        let mut q = start.clone();
        q.compressor_head_max = x[0];
        q.compressor_flow_max = x[1] / 10.0;
        q
    };
    let ellipse = |x: &[f64]| {
        if !(x[0] > 0.0 && x[1] > 0.0) {
            return None;
        }
        let c = Consts::new(&make(x)).compressor;
        Some(pts.iter().map(|(psi, phi, _)| c.phi(*psi) - phi).collect())
    };
    let psi_top = pts.iter().map(|p| p.0).fold(0.0, f64::max);
    let x0 = [
        psi_top * 1.05,
        pts.iter().map(|p| p.1).fold(0.0, f64::max) * 10.0,
    ];
    let s = solved(
        levenberg_marquardt(ellipse, &x0, &[1.0, 1.0], &LmOptions::default()),
        "compressor ellipse",
    )?;
    let fitted = make(&s.x);
    let eff = |x: &[f64]| {
        if !(x[0] > 0.0 && x[1] > 0.0) {
            return None;
        }
        let mut q = fitted.clone();
        q.compressor_efficiency_max = x[0];
        q.compressor_flow_at_efficiency_max = x[1] / 10.0;
        let c = Consts::new(&q).compressor;
        Some(
            pts.iter()
                .map(|(_, phi, eta)| c.efficiency(*phi) - eta)
                .collect(),
        )
    };
    let x0 = [
        pts.iter().map(|p| p.2).fold(0.0, f64::max),
        start.compressor_flow_at_efficiency_max * 10.0,
    ];
    let e = solved(
        levenberg_marquardt(eff, &x0, &[1.0, 1.0], &LmOptions::default()),
        "compressor efficiency",
    )?;
    Ok(CompressorFit {
        head_max: estimate(&s, 0, 1.0),
        flow_max: estimate(&s, 1, 0.1),
        rms_phi: s.residual_rms,
        efficiency_max: estimate(&e, 0, 1.0),
        flow_at_efficiency_max: estimate(&e, 1, 0.1),
        rms_eta: e.residual_rms,
        points: map.len(),
    })
}

/// The compressor at an engine-map point, as the model with parameters `c` runs it: the outlet
/// pressure upstream of the intercooler restriction from `p_bef_thr` at the air flow, the turbo
/// speed at which the model's compressor passes the air flow at that pressure ratio, and what
/// it then delivers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompressorState {
    /// Compressor outlet pressure (Pa).
    pub p_c_pa: f64,
    /// Compressor outlet temperature (K).
    pub t_c_k: f64,
    /// Turbo speed (rad/s), within the model's limits.
    pub omega_rad_s: f64,
    /// Absorbed power (W).
    pub power_w: f64,
}

/// [`CompressorState`] at point `p` with the model constants `c`; `None` where the model's compressor cannot pass the flow
/// at that pressure ratio even at its top speed. At the lowest speed it passes more than the
/// flow at low load; the state is then the one at the lowest speed (the model's stationary
/// point holds the speed at its limit there too).
pub(crate) fn compressor_state(c: &Consts, p: &EnginePoint) -> Option<CompressorState> {
    let w = p.air_flow_kg_s;
    let mut t_c = p.t_ic_k;
    let mut state = None;
    // The intercooler restriction's flow depends on its upstream temperature, which depends on
    // the pressure ratio: three fixed-point passes settle it to far below a pascal.
    for _ in 0..3 {
        let p_c = upstream_pressure(&c.intercooler, p.p_ic_pa, t_c, w)?;
        let flow = |omega: f64| c.compressor.point(p.p_af_pa, p.t_af_k, p_c, t_c, omega).w;
        let (lo, hi) = (c.shaft.omega_min, c.shaft.omega_max);
        if !(flow(hi) >= w) {
            return None;
        }
        let omega = if flow(lo) >= w {
            lo
        } else {
            let (mut a, mut b) = (lo, hi);
            for _ in 0..BISECTION_STEPS {
                let mid = 0.5 * (a + b);
                if flow(mid) < w {
                    a = mid;
                } else {
                    b = mid;
                }
            }
            0.5 * (a + b)
        };
        let pt = c.compressor.point(p.p_af_pa, p.t_af_k, p_c, t_c, omega);
        t_c = pt.t_out;
        state = Some(CompressorState {
            p_c_pa: p_c,
            t_c_k: pt.t_out,
            omega_rad_s: omega,
            power_w: pt.torque * omega,
        });
    }
    state
}

/// Intercooler effectiveness: `T_bef_thr = T_c - eps (T_c - T_af)` with the compressor model's
/// outlet temperature `T_c` at each point ([`CompressorState`]), linear least squares in
/// `eps` (points with little boost, where `T_c` is near `T_af`, carry little weight by
/// themselves). The map has no compressor-outlet pressure or temperature: the intercooler's
/// resistance `H` is not determined and stays at the start file's value (it sets the
/// compressor-outlet pressure the other fits assume).
pub fn fit_intercooler(
    points: &[EnginePoint],
    params: &TurboParams,
) -> Result<IntercoolerFit, FitError> {
    let c = &Consts::new(params);
    let rows: Vec<(f64, f64)> = points
        .iter()
        .filter_map(|p| compressor_state(c, p).map(|s| (s.t_c_k - p.t_ic_k, s.t_c_k - p.t_af_k)))
        .collect();
    need("intercooler", rows.len(), 2)?;
    let den: f64 = rows.iter().map(|(_, b)| b * b).sum();
    if !(den > 0.0) {
        return Err(FitError::Solver {
            what: "intercooler",
            reason: "no compressor temperature rise at any point",
        });
    }
    let eps = (rows.iter().map(|(a, b)| a * b).sum::<f64>() / den).clamp(0.0, 1.0);
    Ok(IntercoolerFit {
        effectiveness: eps,
        rms_k: rms(rows.iter().map(|(a, b)| eps * b - a)),
        points: rows.len(),
    })
}

/// Turbine from the engine map. The map has no wastegate position. At a boost ratio
/// `p_bef_thr / p_af` of at least [`FitOptions::closed_wastegate_boost_ratio`] the turbine must
/// supply the compressor's work, and the wastegate is taken as closed: the whole exhaust flow
/// passes the turbine. The threshold trades the whole-model errors of `p_ic`/`p_im` against
/// `p_em` (RMSE in % of the mean over all 344 points, `p_ic, p_im, p_em, m_dot_at`): 1.02 gives
/// 1.2, 2.6, 8.3, 5.0; 1.1 gives 3.1, 4.4, 7.0; 1.3 (our first choice) 5.4, 6.9, 5.3, 7.6; 1.5
/// gives 8.9, 11.5, 7.0. A high threshold fits the turbine to the steep high-load end, where it
/// then passes too much flow at low load and the closed wastegate no longer gives the measured
/// boost; 1.02 was chosen after this comparison. There, `k1` is fitted by Levenberg-Marquardt on the relative flow
/// residual of the model's turbine at the measured `p_em, T_em, p_t`. `k2` stays at the start
/// file's value: the measured flow parameter `W sqrt(T_em) / p_em` rises more steeply with the
/// expansion ratio (0.0100 at 1.25, 0.0218 at 1.70 kg K^0.5/(s kPa)) than
/// `k1 sqrt(1 - Pi_t^k2)` can for any `k2 > 0` (a free `k2` runs to 0 with `k1 sqrt(k2)`
/// fixed), a sign of the turbine's flow growing with its speed or of the wastegate opening with
/// the load, neither of which the form has; so `k2` is not determined. Then the efficiency
/// parabola's peak `eta_max` on the relative torque residual: the torque the model's turbine
/// delivers at the turbo speed the compressor model needs ([`CompressorState`]) against the
/// compressor's torque plus the shaft friction. `BSR_opt` and the turbine diameter stay at the
/// start file's values: with the first threshold tried (1.3) the points spanned blade speed
/// ratios of only 0.60 to 0.66 and a free `BSR_opt` ran off with `eta_max` beyond 1; the range
/// the points span is reported ([`TurbineFit::bsr_range`]).
pub fn fit_turbine(
    points: &[EnginePoint],
    params: &TurboParams,
    opts: &FitOptions,
) -> Result<TurbineFit, FitError> {
    let c = &Consts::new(params);
    let afs = params.stoichiometric_air_fuel_ratio;
    let boosted: Vec<&EnginePoint> = points
        .iter()
        .filter(|p| p.p_ic_pa / p.p_af_pa >= opts.closed_wastegate_boost_ratio)
        .collect();
    need("turbine", boosted.len(), 4)?;
    let make = |x: &[f64]| {
        let mut q = params.clone();
        q.turbine_flow_k1_kg_k05_per_s_kpa = x[0] / 100.0;
        q
    };
    let flow = |x: &[f64]| {
        if !(x[0] > 0.0) {
            return None;
        }
        let t = Consts::new(&make(x)).turbine;
        Some(
            boosted
                .iter()
                .map(|p| {
                    let w = exhaust_flow(p, afs);
                    (t.point(p.p_em_pa, p.t_em_k, p.p_t_pa, p.t_t_k, 1e4).w - w) / w
                })
                .collect(),
        )
    };
    let x0 = [params.turbine_flow_k1_kg_k05_per_s_kpa * 100.0];
    let s = solved(
        levenberg_marquardt(flow, &x0, &[1.0], &LmOptions::default()),
        "turbine flow",
    )?;
    let with_flow = make(&s.x);
    let t_flow = Consts::new(&with_flow).turbine;
    let unboosted: Vec<f64> = points
        .iter()
        .filter(|p| p.p_ic_pa / p.p_af_pa < opts.closed_wastegate_boost_ratio)
        .map(|p| {
            let w = exhaust_flow(p, afs);
            (w - t_flow.point(p.p_em_pa, p.t_em_k, p.p_t_pa, p.t_t_k, 1e4).w) / w
        })
        .collect();
    let needs: Vec<(&EnginePoint, f64, f64)> = boosted
        .iter()
        .filter_map(|p| {
            let st = compressor_state(c, p)?;
            let torque = st.power_w / st.omega_rad_s + c.shaft.friction * st.omega_rad_s;
            Some((*p, st.omega_rad_s, torque))
        })
        .collect();
    need("turbine efficiency", needs.len(), 3)?;
    let eff = |x: &[f64]| {
        if !(x[0] > 0.0 && x[0] <= 1.0) {
            return None;
        }
        let mut q = with_flow.clone();
        q.turbine_efficiency_max = x[0];
        let t = Consts::new(&q).turbine;
        Some(
            needs
                .iter()
                .map(|(p, omega, tq)| {
                    (t.point(p.p_em_pa, p.t_em_k, p.p_t_pa, p.t_t_k, *omega)
                        .torque
                        - tq)
                        / tq
                })
                .collect(),
        )
    };
    let e = solved(
        levenberg_marquardt(
            eff,
            &[params.turbine_efficiency_max],
            &[1.0],
            &LmOptions::default(),
        ),
        "turbine efficiency",
    )?;
    let bsr: Vec<f64> = needs
        .iter()
        .map(|(p, omega, _)| {
            t_flow
                .point(p.p_em_pa, p.t_em_k, p.p_t_pa, p.t_t_k, *omega)
                .bsr
        })
        .collect();
    Ok(TurbineFit {
        k1: estimate(&s, 0, 0.01),
        rms_flow_rel: s.residual_rms,
        efficiency_max: estimate(&e, 0, 1.0),
        bsr_range: (
            bsr.iter().copied().fold(f64::INFINITY, f64::min),
            bsr.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        ),
        rms_torque_rel: e.residual_rms,
        points: boosted.len(),
        unboosted_bypass_share: if unboosted.is_empty() {
            0.0
        } else {
            unboosted.iter().sum::<f64>() / unboosted.len() as f64
        },
        unboosted_points: unboosted.len(),
    })
}

/// The turbine map with the model's forms, for the report: `TFP = k1 sqrt(1 - (1/PiT)^k2)`
/// (the model's flow with `p_em` in kPa, if the map's flow parameter is in those units) and the
/// efficiency parabola in the blade speed ratio at `T03` with the model's turbine diameter.
/// Also the median ratio of the engine map's exhaust flow parameter to the map's at the same
/// expansion ratio, over the boosted training points: about 4.5, which is why the turbine is
/// fitted from the engine map (a map 4.5 times too small in flow would need a wastegate passing
/// nearly 80 % of the exhaust at full boost).
pub fn fit_turbine_map(
    map: &[TurbineMapPoint],
    engine: &[EnginePoint],
    params: &TurboParams,
    opts: &FitOptions,
) -> Result<TurbineMapFit, FitError> {
    need("turbine map", map.len(), 4)?;
    let flow = |x: &[f64]| {
        if !(x[0] > 0.0 && x[1] > 0.0) {
            return None;
        }
        Some(
            map.iter()
                .map(|m| {
                    x[0] / 100.0 * (1.0 - m.pressure_ratio.powf(-x[1])).max(0.0).sqrt()
                        - m.flow_parameter
                })
                .collect(),
        )
    };
    let s = solved(
        levenberg_marquardt(flow, &[1.0, 1.5], &[1.0, 1.0], &LmOptions::default()),
        "turbine map flow",
    )?;
    let c = Consts::new(params).turbine;
    let t03 = opts.turbine_reference_temperature_k;
    let bsr: Vec<f64> = map
        .iter()
        .map(|m| {
            let omega = m.speed_parameter * t03.sqrt() * 2.0 * PI / 60.0;
            let y = 1.0 - m.pressure_ratio.powf(-c.expo);
            omega * c.radius / (2.0 * c.cp * t03 * y).sqrt()
        })
        .collect();
    let eff = |x: &[f64]| {
        if !(x[0] > 0.0 && x[1] > 0.0) {
            return None;
        }
        Some(
            map.iter()
                .zip(&bsr)
                .map(|(m, b)| {
                    let q = (b - x[1]) / x[1];
                    x[0] * (1.0 - q * q) - m.efficiency
                })
                .collect(),
        )
    };
    let e = solved(
        levenberg_marquardt(eff, &[0.8, 0.6], &[1.0, 1.0], &LmOptions::default()),
        "turbine map efficiency",
    )?;
    let afs = params.stoichiometric_air_fuel_ratio;
    let (k1, k2) = (s.x[0] / 100.0, s.x[1]);
    let mut ratios: Vec<f64> = engine
        .iter()
        .filter(|p| p.p_ic_pa / p.p_af_pa >= opts.closed_wastegate_boost_ratio)
        .map(|p| {
            let tfp = exhaust_flow(p, afs) * p.t_em_k.sqrt() / (p.p_em_pa / 1000.0);
            tfp / (k1 * (1.0 - (p.p_t_pa / p.p_em_pa).powf(k2)).max(1e-12).sqrt())
        })
        .collect();
    ratios.sort_by(f64::total_cmp);
    let median = ratios.get(ratios.len() / 2).copied().unwrap_or(f64::NAN);
    Ok(TurbineMapFit {
        k1,
        k2,
        efficiency_max: e.x[0],
        bsr_at_efficiency_max: e.x[1],
        engine_to_map_flow_ratio: median,
        points: map.len(),
    })
}

/// Runs every fit from the start parameters and returns the calibrated, validated set. The
/// engine constants (displacement, compression ratio, stoichiometric air/fuel ratio) come from
/// `opts`; every parameter no fit touches keeps the start file's value.
pub fn fit_turbo(
    start: &TurboParams,
    data: &FitData,
    opts: &FitOptions,
) -> Result<FitOutcome, FitError> {
    let mut p = with_constants(start, opts);
    let training: Vec<EnginePoint> = data
        .engine
        .iter()
        .enumerate()
        .filter(|(i, _)| !opts.is_held_out(*i))
        .map(|(_, e)| *e)
        .collect();
    let held_out_points = data.engine.len() - training.len();

    let air_filter = fit_air_filter(&training, &p)?;
    p.air_filter_resistance_pa2_s2_per_kg2_k = air_filter.resistance.value;
    let p_amb = air_filter.ambient_pressure_pa.value;

    let exhaust = fit_exhaust(&training, &p, p_amb)?;
    p.exhaust_resistance_pa2_s2_per_kg2_k = exhaust.resistance.value;

    let vol_eff = fit_vol_eff(&training, &p)?;
    p.vol_eff_factor = 1.0;
    p.vol_eff_poly_kpa = vol_eff.poly_kpa;
    p.vol_eff_poly_min_kpa = vol_eff.min_kpa;
    p.vol_eff_poly_max_kpa = vol_eff.max_kpa;

    let throttle = fit_throttle(&training, &p)?;
    p.throttle_area_coeffs_m2_rad = throttle.coeffs;

    let exhaust_temp = fit_exhaust_temp(&training, &p)?;
    p.exhaust_temp_zero_flow_k = exhaust_temp.t0_k.value;
    p.exhaust_temp_flow_gain_k_s_per_kg = exhaust_temp.c_eo.value;
    p.exhaust_pipe_length_m = exhaust_temp.pipe_length_m.value;

    let compressor = fit_compressor(&data.compressor_map, &p, opts)?;
    p.compressor_head_max = compressor.head_max.value;
    p.compressor_flow_max = compressor.flow_max.value;
    p.compressor_efficiency_max = compressor.efficiency_max.value;
    p.compressor_flow_at_efficiency_max = compressor.flow_at_efficiency_max.value;

    let intercooler = fit_intercooler(&training, &p)?;
    p.intercooler_effectiveness = intercooler.effectiveness;

    let turbine = fit_turbine(&training, &p, opts)?;
    p.turbine_flow_k1_kg_k05_per_s_kpa = turbine.k1.value;
    p.turbine_efficiency_max = turbine.efficiency_max.value;

    let turbine_map = fit_turbine_map(&data.turbine_map, &training, &p, opts)?;

    p.validate()?;
    Ok(FitOutcome {
        params: p,
        report: FitReport {
            air_filter,
            exhaust,
            vol_eff,
            throttle,
            exhaust_temp,
            compressor,
            intercooler,
            turbine,
            turbine_map,
            training_points: training.len(),
            held_out_points,
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn restriction_inversions_invert_the_model_flow() {
        let r = Restriction {
            h: 2e8,
            dp_lin: 2000.0,
        };
        for w in [0.001, 0.02, 0.15] {
            let p_ds = downstream_pressure(&r, 101_300.0, 298.0, w).expect("reachable");
            assert!((r.flow(101_300.0, 298.0, p_ds, 298.0).0 - w).abs() < 1e-12 * w.max(1.0));
            let p_us = upstream_pressure(&r, 101_300.0, 700.0, w).expect("reachable");
            assert!((r.flow(p_us, 700.0, 101_300.0, 700.0).0 - w).abs() < 1e-12 * w.max(1.0));
        }
        assert!(downstream_pressure(&r, 101_300.0, 298.0, 100.0).is_none());
    }
}
