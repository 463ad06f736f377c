//! The component fits, in the order they depend on each other, and [`fit_turbo`], which runs
//! them all from a start parameter set.
//!
//! | component | form (the model's) | data | fitted |
//! |---|---|---|---|
//! | air filter | restriction from ambient to `p_af` | `p_af`, `T_af`, air flow | ambient pressure, `H` |
//! | exhaust system | restriction from `p_t` to ambient | `p_t`, `T_t`, air + fuel flow | `H` |
//! | volumetric efficiency | `(poly4(p_im) + s1 n + s2 n^2) (r_c - (p_em/p_im)^(1/k_e))/(r_c - 1) p_im V_d w_e/(4 pi R T)` | `p_im`, `p_em`, `T_bef_thr`, N, air flow | 5 + 2 coefficients (`C_eta_vol` 1) |
//! | throttle | `A(th) = a0 + a1 th + a2 th^2` in the `k_th` flow function (linear from 0.99) | `p_bef_thr`, `T_bef_thr`, `p_im`, alpha, air flow | `a0, a1, a2` |
//! | exhaust temperature | `T_0 + C_eo W_eo`, pipe heat loss | `T_em`, `T_af`, air + fuel flow | `T_0`, `C_eo`, pipe length |
//! | compressor | Psi-Phi ellipse, efficiency parabola in Phi | compressor map | `Psi_max`, `Phi_max`, `eta_max`, `Phi_opt` |
//! | intercooler | outlet `T_c - eps (T_c - T_amb)` | `T_bef_thr`, the compressor model's `T_c` | `eps` |
//! | turbine efficiency | parabola in the blade speed ratio | turbine map | `eta_max`, `BSR_opt` |
//! | turbine flow | `k1 p_em / sqrt(T_em) sqrt(1 - Pi_t^k2)`, linear in `1 - Pi_t` over the mapped ratios | `p_em`, `p_t`, `T_em`, the flow the compressor model's power implies | `k1` (and where the linear part starts) |
//!
//! Decisions (each explained at its function): the ambient pressure is one constant for the
//! whole map, fitted with the air filter; the ambient temperature is each point's `T_af`; the
//! volumetric efficiency is fitted with the throttle-inlet temperature, which is the manifold
//! temperature of the model (adiabatic throttle and manifold); no point is assumed to have its
//! wastegate closed: the turbine's flow is what the power balance implies ([`fit_turbine`]);
//! the turbine map gives the efficiency, while its flow parameter (4 to 5 times below what the
//! engine's turbine passes) is only reported.

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
    /// Speed terms `[s1, s2]` per 1000 rpm.
    pub speed_coeffs_krpm: [f64; 2],
    /// Speed range (1000 rpm): the training points', rounded outwards to 0.1.
    pub speed_min_krpm: f64,
    /// Upper end (1000 rpm).
    pub speed_max_krpm: f64,
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
    /// First step: RMS of the relative flow (= area) residual (-).
    pub area_rms_rel: f64,
    /// First step: points used (those where the throttle restricts: `p_im / p_bef_thr` below
    /// [`THROTTLE_MAX_RATIO`]).
    pub area_points: usize,
    /// Second step: RMS of the manifold-pressure residual at all points (Pa).
    pub rms_p_im_pa: f64,
    /// Second step: points used (all).
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

/// The turbine flow fit from the engine map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurbineFit {
    /// `k1` (kg K^0.5 / (s kPa)), with the linear continuation from [`Self::linear_ratio`].
    pub k1: Estimate,
    /// `turbine_linear_ratio`: the smallest mapped `Pi_t`, rounded down to 0.05 (-).
    pub linear_ratio: f64,
    /// RMS of the residual against the turbine flow the power balance implies (kg/s).
    pub rms_kg_s: f64,
    /// The same for the square-root form `k1 sqrt(1 - Pi_t^k2)` with `k1, k2` free (kg/s).
    pub sqrt_form_rms_kg_s: f64,
    /// The `k2` that form's fit ends at (-).
    pub sqrt_form_k2: f64,
    /// The blade speed ratios of the working points (min, max) (-).
    pub bsr_range: (f64, f64),
    /// Points used: the working points whose implied turbine flow is positive and at most the
    /// exhaust flow.
    pub points: usize,
    /// Points where the compressor works (turbo speed above the model's lowest).
    pub working_points: usize,
    /// Share of the exhaust flow the fitted turbine does not pass at the points used, i.e. what
    /// the wastegate passes (mean, max) (-).
    pub bypass_share: (f64, f64),
}

/// The turbine map: its flow fitted with the model's form (reported only), its efficiency
/// parabola (used).
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
    /// RMS of the efficiency residual (-).
    pub rms_eta: f64,
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
    /// Turbine flow from the engine map.
    pub turbine: TurbineFit,
    /// Turbine map (its efficiency used, its flow reported).
    pub turbine_map: TurbineMapFit,
    /// Shaft loss torque from a measured turbo speed (with it, `turbine` is the refit), if the
    /// data had an anchor.
    pub shaft: Option<super::ShaftFit>,
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

/// Volumetric efficiency: the model's cylinder flow with the factor `poly4(p_im) + s1 n + s2 n^2`
/// (`C_eta_vol` 1, `n` the engine speed in 1000 rpm), which is linear in its seven
/// coefficients, fitted by linear least squares on the air flow in kg/s (so the high-flow points,
/// where the air flow and the manifold pressure are largest, weigh as the whole-model RMSE
/// figures weigh them). The temperature is the measured throttle-inlet temperature
/// `T_bef_thr`, not `T_im`: the model's throttle and manifold are adiabatic, so its `T_im` is its
/// intercooler temperature, while the measured manifold is up to 15 K warmer than the throttle
/// inlet at low load (heated by the engine); a fit on `T_im` would make the whole model's flow
/// that much too high there.
///
/// The speed terms: a factor of `p_im` alone leaves a 3.9 % RMS air-flow residual at the
/// TSFS09 training points (whole model 5.0 %), largest at 4300 rpm and low load: the breathing
/// of a real engine depends on its speed (valve-flow friction grows with the gas velocity,
/// intake tuning helps at mid speeds). The form is the additive one of Eriksson and Nielsen
/// (2014, eq. 7.12), `eta = f(p_im) + g(N)`, with `g` a quadratic without constant as Guzzella
/// and Onder's `eta_omega` (the constant is the polynomial's). Two parameters; the argument is
/// clamped to the training points' speed range (the quadratic is not to be extrapolated).
pub fn fit_vol_eff(points: &[EnginePoint], start: &TurboParams) -> Result<VolEffFit, FitError> {
    fit_vol_eff_order(points, start, 4)
}

/// [`fit_vol_eff`] with the polynomial in `p_im` of order `order` (at most 4; the higher
/// coefficients are 0): for data that span a narrow `p_im` range, where a 4th-order polynomial
/// is not determined (a driving log of a city cycle).
pub fn fit_vol_eff_order(
    points: &[EnginePoint],
    start: &TurboParams,
    order: usize,
) -> Result<VolEffFit, FitError> {
    let order = order.min(4);
    let cols = order + 3;
    need("volumetric efficiency", points.len(), cols + 1)?;
    // Ranges rounded outwards to `1 / per` (dividing by an integer keeps 0.7 exactly 0.7).
    let range = |f: &dyn Fn(&EnginePoint) -> f64, per: f64| {
        let lo = points.iter().map(f).fold(f64::INFINITY, f64::min);
        let hi = points.iter().map(f).fold(f64::NEG_INFINITY, f64::max);
        ((lo * per).floor() / per, (hi * per).ceil() / per)
    };
    let (lo, hi) = range(&|p| p.p_im_pa / 1000.0, 1.0);
    let (n_lo, n_hi) = range(&|p| p.engine_speed_rev_s * 60.0 / 1000.0, 10.0);
    let mut base = start.clone();
    base.vol_eff_factor = 1.0;
    base.vol_eff_poly_kpa = [0.0, 0.0, 0.0, 0.0, 1.0];
    base.vol_eff_poly_min_kpa = lo;
    base.vol_eff_poly_max_kpa = hi;
    base.vol_eff_speed_coeffs_krpm = [0.0, 0.0];
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
    let a = DMatrix::from_fn(points.len(), cols, |i, j| {
        let x = (points[i].p_im_pa / 1000.0).clamp(lo, hi);
        let n = (points[i].engine_speed_rev_s * 60.0 / 1000.0).clamp(n_lo, n_hi);
        let term = if j <= order {
            x.powi((order - j) as i32)
        } else if j == order + 1 {
            n
        } else {
            n * n
        };
        flows[i] * term
    });
    let b = DVector::from_iterator(points.len(), points.iter().map(|p| p.air_flow_kg_s));
    let c = linear_least_squares(&a, &b).ok_or(FitError::Solver {
        what: "volumetric efficiency",
        reason: "singular",
    })?;
    let fitted = &a * &c;
    let mut poly_kpa = [0.0; 5];
    for j in 0..=order {
        poly_kpa[4 - order + j] = c[j];
    }
    Ok(VolEffFit {
        poly_kpa,
        min_kpa: lo,
        max_kpa: hi,
        speed_coeffs_krpm: [c[order + 1], c[order + 2]],
        speed_min_krpm: n_lo,
        speed_max_krpm: n_hi,
        rms_kg_s: rms(fitted.iter().zip(b.iter()).map(|(f, m)| f - m)),
        rms_rel: rms(fitted.iter().zip(b.iter()).map(|(f, m)| (f - m) / m)),
        points: points.len(),
    })
}

/// Throttle, in two steps. First the effective area each point implies, `W / (flow per unit
/// area)` with the model's flow function (its `k_th` and linear continuation) at the measured
/// `p_bef_thr, T_bef_thr, p_im`, fitted by the quadratic in the plate angle (the start file's
/// angle map, `th = gain alpha + offset`) with relative weights (each point's flow error in
/// percent counts alike, from 3 to 150 g/s), at the points where the throttle restricts
/// (`p_im / p_bef_thr` below [`THROTTLE_MAX_RATIO`]): linear least squares, the start of the
/// second step. Second, the three coefficients by Levenberg-Marquardt on the **manifold
/// pressure** the throttle gives (the pressure downstream at which the model's throttle passes
/// the measured flow from the measured `p_bef_thr, T_bef_thr`, in Pa) at every point,
/// including the nearly wide-open ones. The area a point implies is meaningless near wide open
/// (a small difference of two nearly equal pressures), but its pressure drop is not: the
/// pressure residual weighs each point by how much its area matters to `p_im`, which is what
/// the whole model is judged on. Without the second step the quadratic fitted at the
/// restricting points gave too small an area at wide open (the model's `p_im` 5 kPa, 2.8 %,
/// below the measured at 4300 rpm and full load, and the air flow with it).
pub fn fit_throttle(points: &[EnginePoint], start: &TurboParams) -> Result<ThrottleFit, FitError> {
    let c = Consts::new(start);
    let angle = |p: &EnginePoint| {
        (start.throttle_angle_gain_deg_per_pct * p.throttle_frac * 100.0
            + start.throttle_angle_offset_deg)
            * PI
            / 180.0
    };
    let rows: Vec<(f64, f64)> = points
        .iter()
        .filter(|p| p.p_im_pa / p.p_ic_pa < THROTTLE_MAX_RATIO)
        .map(|p| {
            let per_area = c
                .throttle
                .nozzle
                .flow(1.0, p.p_ic_pa, p.t_ic_k, p.p_im_pa, p.t_im_k)
                .0;
            (angle(p), p.air_flow_kg_s / per_area)
        })
        .filter(|(_, a)| a.is_finite() && *a > 0.0)
        .collect();
    need("throttle", rows.len(), 4)?;
    need("throttle", points.len(), 4)?;
    let a = DMatrix::from_fn(rows.len(), 3, |i, j| rows[i].0.powi(j as i32) / rows[i].1);
    let b = DVector::from_element(rows.len(), 1.0);
    let x = linear_least_squares(&a, &b).ok_or(FitError::Solver {
        what: "throttle",
        reason: "singular",
    })?;
    let fitted = &a * &x;
    let area_rms_rel = rms(fitted.iter().map(|f| f - 1.0));
    // Second step: the manifold-pressure error each point's flow error causes, to first order
    // in the whole model: dp_im = dW / (dW_cyl/dp_im - dW_th/dp_im), with dW_cyl/dp_im about
    // W / p_im (the cylinder flow is about proportional to p_im) and dW_th/dp_im the throttle's
    // (0 when choked, large near wide open) at the first step's area. The residual is linear
    // in the coefficients with these fixed weights: weighted linear least squares, twice (the
    // second pass with the weights at the first pass's area).
    let nozzle = &c.throttle.nozzle;
    let per_area: Vec<(f64, f64, f64)> = points
        .iter()
        .map(|p| {
            let f = |p_ds: f64| nozzle.flow(1.0, p.p_ic_pa, p.t_ic_k, p_ds, p.t_ic_k).0;
            let h = 1.0;
            let slope = (f(p.p_im_pa + h) - f(p.p_im_pa - h)) / (2.0 * h);
            (angle(p), f(p.p_im_pa), slope)
        })
        .collect();
    let mut coeffs = [x[0], x[1], x[2]];
    let mut rms_p_im_pa = f64::NAN;
    for _ in 0..2 {
        let weights: Vec<f64> = points
            .iter()
            .zip(&per_area)
            .map(|(p, (th, _, slope))| {
                let area = coeffs[0] + th * (coeffs[1] + th * coeffs[2]);
                1.0 / (p.air_flow_kg_s / p.p_im_pa - area * slope)
            })
            .collect();
        let a = DMatrix::from_fn(points.len(), 3, |i, j| {
            per_area[i].0.powi(j as i32) * per_area[i].1 * weights[i]
        });
        let b = DVector::from_iterator(
            points.len(),
            points
                .iter()
                .zip(&weights)
                .map(|(p, w)| p.air_flow_kg_s * w),
        );
        let x = linear_least_squares(&a, &b).ok_or(FitError::Solver {
            what: "throttle",
            reason: "singular",
        })?;
        rms_p_im_pa = rms((&a * &x - &b).iter().copied());
        coeffs = [x[0], x[1], x[2]];
    }
    Ok(ThrottleFit {
        coeffs,
        area_rms_rel,
        area_points: rows.len(),
        rms_p_im_pa,
        points: points.len(),
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
    base.vol_eff_speed_coeffs_krpm = [0.0, 0.0];
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

/// Turbine flow from the engine map, **without assuming where the wastegate is closed**. The
/// map has no wastegate position, so the exhaust flow does not say how much of it passed the
/// turbine. The power balance does: at each point the turbine delivers the compressor's power
/// (the compressor model's power at the turbo speed it needs, [`CompressorState`], plus the
/// shaft's friction losses), so with the turbine's efficiency known the flow through the turbine is
/// `W_t = P / (cp_e T_em eta_t(BSR) (1 - Pi_t^((k_e-1)/k_e)))` at the measured `p_em, T_em, p_t`,
/// whatever the wastegate passed. The efficiency is the turbine map's ([`fit_turbine_map`]:
/// the parabola in the blade speed ratio, `eta_max` and `BSR_opt`, dimensionless and measured
/// on the gas stand), set in `params` by the caller. The points used are those where the
/// compressor works (turbo speed above the model's lowest, so that the power is the
/// compressor's and not a floor) and the implied flow is physical: positive and at most the
/// whole exhaust flow (the rest is the wastegate's, [`TurbineFit::bypass_share`]).
///
/// **The form.** The implied turbine flow rises with the expansion ratio more steeply than
/// `k1 sqrt(1 - Pi_t^k2)` can: fitted with `k1, k2` free, `k2` runs to 0 (the form's steepest
/// shape, `sqrt(k2 ln(1/Pi_t))`) and leaves [`TurbineFit::sqrt_form_rms_kg_s`]. Over the mapped
/// ratios the flow is close to linear in the pressure drop, `W_t ~ (p_em - p_t) / sqrt(T_em)`,
/// which is the model's own continuation of the form above `turbine_linear_ratio` (linear in
/// `1 - Pi_t` to zero at 1). So the continuation is made to start below every mapped ratio (the
/// smallest `Pi_t` of the points used, rounded down to 0.05), and `k1` is fitted: one parameter
/// for the flow, by linear least squares. `k2` then only shapes the flow at expansion ratios
/// beyond the map, which no point determines: it stays at the start file's value. The residual
/// is the flow in kg/s (not relative): the high-flow points, where `p_em` is highest, weigh as
/// in the whole-model RMSE, as for the volumetric efficiency.
///
/// Why not the former rule (the whole exhaust flow through the turbine wherever the boost ratio
/// was at least 1.02, chosen after looking at figures that included held-out points): the boost
/// controller opens the wastegate at high load, so the total flow is not the turbine's there.
pub fn fit_turbine(points: &[EnginePoint], params: &TurboParams) -> Result<TurbineFit, FitError> {
    let c = &Consts::new(params);
    let afs = params.stoichiometric_air_fuel_ratio;
    let t0 = c.turbine;
    let omega_floor = c.shaft.omega_min * (1.0 + 1e-9);
    let all: Vec<(&EnginePoint, f64, f64)> = points
        .iter()
        .filter_map(|p| {
            let st = compressor_state(c, p)?;
            if !(st.omega_rad_s > omega_floor) || !(p.p_em_pa > p.p_t_pa) {
                return None;
            }
            let power = st.power_w + c.shaft.friction_power(st.omega_rad_s);
            // Work per kg through the turbine at the measured state (J/kg): the turbine's own
            // code, whose torque is its flow times that work over the speed.
            let pt = t0.point(p.p_em_pa, p.t_em_k, p.p_t_pa, p.t_t_k, st.omega_rad_s);
            let per_flow = pt.torque * st.omega_rad_s / pt.w;
            if !(per_flow > 0.0) {
                return None;
            }
            Some((p, st.omega_rad_s, power / per_flow))
        })
        .collect();
    let used: Vec<(&EnginePoint, f64)> = all
        .iter()
        .filter(|(p, _, w_t)| *w_t > 0.0 && *w_t <= exhaust_flow(p, afs))
        .map(|(p, _, w_t)| (*p, *w_t))
        .collect();
    need("turbine flow", used.len(), 4)?;
    let min_ratio = used
        .iter()
        .map(|(p, _)| p.p_t_pa / p.p_em_pa)
        .fold(1.0, f64::min);
    let linear_ratio = ((min_ratio * 20.0).floor() / 20.0).max(0.05);
    // Flow per unit k1 at each point (the form is linear in k1).
    let unit_flow = |q: &TurboParams, p: &EnginePoint| {
        let mut q = q.clone();
        q.turbine_flow_k1_kg_k05_per_s_kpa = 1.0;
        Consts::new(&q)
            .turbine
            .point(p.p_em_pa, p.t_em_k, p.p_t_pa, p.t_t_k, 1e4)
            .w
    };
    let mut linear = params.clone();
    linear.turbine_linear_ratio = linear_ratio;
    let units: Vec<f64> = used.iter().map(|(p, _)| unit_flow(&linear, p)).collect();
    let den: f64 = units.iter().map(|u| u * u).sum();
    if !(den > 0.0) {
        return Err(FitError::Solver {
            what: "turbine flow",
            reason: "no pressure drop at any point",
        });
    }
    let k1 = units
        .iter()
        .zip(&used)
        .map(|(u, (_, w))| u * w)
        .sum::<f64>()
        / den;
    let resid: Vec<f64> = units
        .iter()
        .zip(&used)
        .map(|(u, (_, w))| k1 * u - w)
        .collect();
    let rms_kg_s = rms(resid.iter().copied());
    let n = used.len() as f64;
    let k1_se = (resid.iter().map(|r| r * r).sum::<f64>() / (n - 1.0) / den).sqrt();
    // The square-root form with k1 and k2 free, for comparison (reported only).
    let sqrt_form = |x: &[f64]| {
        if !(x[0] > 0.0 && x[1] > 0.0 && x[1] < 10.0) {
            return None;
        }
        let mut q = params.clone();
        q.turbine_flow_k2 = x[1];
        Some(
            used.iter()
                .map(|(p, w)| x[0] / 100.0 * unit_flow(&q, p) - w)
                .collect::<Vec<f64>>(),
        )
    };
    let x0 = [k1 * 100.0, params.turbine_flow_k2];
    let sq = solved(
        levenberg_marquardt(sqrt_form, &x0, &[1.0, 1.0], &LmOptions::default()),
        "turbine flow (square-root form)",
    )?;
    linear.turbine_flow_k1_kg_k05_per_s_kpa = k1;
    let t = Consts::new(&linear).turbine;
    let shares: Vec<f64> = used
        .iter()
        .map(|(p, _)| {
            let w = exhaust_flow(p, afs);
            (w - t.point(p.p_em_pa, p.t_em_k, p.p_t_pa, p.t_t_k, 1e4).w) / w
        })
        .collect();
    let bsr: Vec<f64> = all
        .iter()
        .map(|(p, omega, _)| t.point(p.p_em_pa, p.t_em_k, p.p_t_pa, p.t_t_k, *omega).bsr)
        .collect();
    Ok(TurbineFit {
        k1: Estimate {
            value: k1,
            std_error: k1_se,
        },
        linear_ratio,
        rms_kg_s,
        sqrt_form_rms_kg_s: sq.residual_rms,
        sqrt_form_k2: sq.x[1],
        bsr_range: (
            bsr.iter().copied().fold(f64::INFINITY, f64::min),
            bsr.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        ),
        points: used.len(),
        working_points: all.len(),
        bypass_share: (
            shares.iter().sum::<f64>() / n,
            shares.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        ),
    })
}

/// The turbine map with the model's forms: the efficiency parabola in the blade speed ratio at
/// `T03` with the model's turbine diameter (`eta_max`, `BSR_opt`; used by the model: efficiency
/// and blade speed ratio are dimensionless and the gas stand measures them directly), and
/// `TFP = k1 sqrt(1 - (1/PiT)^k2)` (the model's flow with `p_em` in kPa, if the map's flow
/// parameter is in those units), only reported: the map's flow parameter is 4 to 5 times below
/// the flow the engine's turbine passes by the power balance ([`fit_turbine`]), so its unit or
/// its reference conditions are not the ones we read; the flow is fitted from the engine map.
pub fn fit_turbine_map(
    map: &[TurbineMapPoint],
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
    Ok(TurbineMapFit {
        k1: s.x[0] / 100.0,
        k2: s.x[1],
        efficiency_max: e.x[0],
        bsr_at_efficiency_max: e.x[1],
        rms_eta: e.residual_rms,
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
    p.vol_eff_speed_coeffs_krpm = vol_eff.speed_coeffs_krpm;
    p.vol_eff_speed_min_krpm = vol_eff.speed_min_krpm;
    p.vol_eff_speed_max_krpm = vol_eff.speed_max_krpm;

    p.throttle_linear_ratio = opts.throttle_linear_ratio;
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

    let turbine_map = fit_turbine_map(&data.turbine_map, &p, opts)?;
    p.turbine_efficiency_max = turbine_map.efficiency_max;
    p.turbine_bsr_at_efficiency_max = turbine_map.bsr_at_efficiency_max;

    let mut turbine = fit_turbine(&training, &p)?;
    p.turbine_flow_k1_kg_k05_per_s_kpa = turbine.k1.value;
    p.turbine_linear_ratio = turbine.linear_ratio;

    let shaft = match &data.shaft_anchor {
        Some(anchor) => {
            let (q, fit) = super::shaft::fit_shaft_torque(&training, &p, anchor, p_amb, opts)?;
            p = q;
            turbine = fit.turbine;
            Some(fit)
        }
        None => None,
    };

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
            shaft,
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
