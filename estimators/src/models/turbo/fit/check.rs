//! The whole-model check: the model's stationary point at every engine-map point, with the
//! point's measured inputs, against every measured quantity.
//!
//! Inputs per point: throttle (the map's fraction in percent), engine speed, lambda (the
//! wide-band sensor before the catalyst), the ambient temperature = the point's `T_af` (the
//! model's air filter is adiabatic, so its `T_af` is the ambient one) and one ambient pressure
//! for the whole map (fitted with the air filter, see [`super::components::fit_air_filter`]).
//!
//! **The wastegate** is not measured. It is solved per point so that the model's boost
//! pressure `p_ic` equals the measured `p_bef_thr` (what the engine's boost controller does with
//! it), by the Illinois variant of regula falsi on the position in `[0, 1]`. Where even the
//! closed (open) wastegate gives less (more) boost than measured, the position stays at 0 (1)
//! and `p_ic` keeps its error: [`WastegateSolve`] says which. **`p_ic` is therefore the matched
//! quantity**: its figures measure only the points where the wastegate saturated, and they are
//! not a test of the model like the others.

use super::super::{TurboInput, TurboModel, TurboParams, TurboSignals, TurboState};
use super::{rms, EnginePoint, FitError, FitOptions};

/// The compared quantities: name, unit.
pub const QUANTITIES: [(&str, &str); 10] = [
    ("p_af", "Pa"),
    ("p_ic", "Pa"),
    ("p_im", "Pa"),
    ("p_em", "Pa"),
    ("p_t", "Pa"),
    ("T_ic", "K"),
    ("T_im", "K"),
    ("T_em", "K"),
    ("T_t", "K"),
    ("m_dot_at", "kg/s"),
];

/// Index of `p_ic`, the quantity the wastegate is solved for, in [`QUANTITIES`].
pub const MATCHED_QUANTITY: usize = 1;

/// How the wastegate position of a point was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WastegateSolve {
    /// Solved: the model's `p_ic` equals the measured one (to 1 Pa).
    Matched,
    /// Closed, and still less boost than measured.
    SaturatedClosed,
    /// Open, and still more boost than measured.
    SaturatedOpen,
}

/// One point's result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointCheck {
    /// 0-based index in the map.
    pub index: usize,
    /// Whether the point was held out of the component fits.
    pub held_out: bool,
    /// Wastegate position (0..1).
    pub wastegate: f64,
    /// How it was found.
    pub solve: WastegateSolve,
    /// Turbo speed (rad/s).
    pub turbo_speed_rad_s: f64,
    /// Model values in [`QUANTITIES`] order.
    pub model: [f64; 10],
    /// Measured values.
    pub measured: [f64; 10],
}

/// Error statistics of one quantity over a set of points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuantityStats {
    /// Root mean square error (model - measured) in the quantity's unit.
    pub rmse: f64,
    /// Mean of the measured values.
    pub mean: f64,
    /// `rmse / mean` in percent.
    pub rmse_pct: f64,
    /// Index (0-based, in the map) of the point with the largest absolute error.
    pub worst_index: usize,
    /// Its error (model - measured).
    pub worst_error: f64,
    /// Points.
    pub points: usize,
}

/// The check's result.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckReport {
    /// Every point.
    pub points: Vec<PointCheck>,
    /// Per quantity over all points.
    pub all: [QuantityStats; 10],
    /// Per quantity over the held-out points.
    pub held_out: [QuantityStats; 10],
}

impl CheckReport {
    /// Points whose wastegate saturated closed and open.
    pub fn saturated(&self) -> (usize, usize) {
        let count = |s| self.points.iter().filter(|p| p.solve == s).count();
        (
            count(WastegateSolve::SaturatedClosed),
            count(WastegateSolve::SaturatedOpen),
        )
    }
}

/// Matching tolerance of the model's `p_ic` (Pa).
const MATCH_TOL_PA: f64 = 1.0;
/// Most regula-falsi steps per point.
const MAX_STEPS: usize = 60;

fn values(s: &TurboSignals) -> [f64; 10] {
    [
        s.p_af_pa,
        s.p_ic_pa,
        s.p_im_pa,
        s.p_em_pa,
        s.p_es_pa,
        s.t_ic_k,
        s.t_im_k,
        s.t_em_k,
        s.t_es_k,
        s.w_af_kg_s,
    ]
}

fn measured(p: &EnginePoint) -> [f64; 10] {
    [
        p.p_af_pa,
        p.p_ic_pa,
        p.p_im_pa,
        p.p_em_pa,
        p.p_t_pa,
        p.t_ic_k,
        p.t_im_k,
        p.t_em_k,
        p.t_t_k,
        p.air_flow_kg_s,
    ]
}

/// The model's input at point `p` with wastegate `u_wg`.
pub fn input(p: &EnginePoint, u_wg: f64, ambient_pressure_pa: f64) -> TurboInput {
    TurboInput {
        throttle_pct: p.throttle_frac * 100.0,
        engine_speed_rad_s: super::components::engine_speed_rad_s(p),
        wastegate_frac: u_wg,
        lambda: p.lambda,
        ambient_pressure_pa,
        ambient_temperature_k: p.t_af_k,
    }
}

/// The stationary point at `u`, from `guess` and, if that fails, from the model's default
/// start.
fn stationary(
    model: &TurboModel,
    u: &TurboInput,
    guess: Option<&TurboState>,
) -> Result<TurboState, FitError> {
    match model.stationary_point(u, guess) {
        Ok(s) => Ok(s.state),
        Err(e) if guess.is_some() => model
            .stationary_point(u, None)
            .map(|s| s.state)
            .map_err(|_| FitError::Model(e)),
        Err(e) => Err(FitError::Model(e)),
    }
}

/// Solves one point (see the module docs).
pub fn check_point(
    model: &TurboModel,
    p: &EnginePoint,
    ambient_pressure_pa: f64,
) -> Result<(f64, WastegateSolve, TurboSignals), FitError> {
    let target = p.p_ic_pa;
    let eval = |u_wg: f64, guess: Option<&TurboState>| -> Result<(TurboState, f64), FitError> {
        let u = input(p, u_wg, ambient_pressure_pa);
        let x = stationary(model, &u, guess)?;
        Ok((x, model.signals(&x, &u).p_ic_pa - target))
    };
    let signals =
        |u_wg: f64, x: &TurboState| model.signals(x, &input(p, u_wg, ambient_pressure_pa));
    let (x0, f0) = eval(0.0, None)?;
    if f0 <= MATCH_TOL_PA {
        let solve = if f0 < -MATCH_TOL_PA {
            WastegateSolve::SaturatedClosed
        } else {
            WastegateSolve::Matched
        };
        return Ok((0.0, solve, signals(0.0, &x0)));
    }
    let (x1, f1) = eval(1.0, Some(&x0))?;
    if f1 >= -MATCH_TOL_PA {
        let solve = if f1 > MATCH_TOL_PA {
            WastegateSolve::SaturatedOpen
        } else {
            WastegateSolve::Matched
        };
        return Ok((1.0, solve, signals(1.0, &x1)));
    }
    // Illinois: f(a) > 0 > f(b); the retained end's value is halved when the same end is kept
    // twice, which keeps regula falsi from stalling on a curved function.
    let (mut a, mut fa, mut xa) = (0.0, f0, x0);
    let (mut b, mut fb, mut xb) = (1.0, f1, x1);
    let mut side = 0i8;
    for _ in 0..MAX_STEPS {
        let c = ((a * fb - b * fa) / (fb - fa)).clamp(a, b);
        let guess = if c - a < b - c { xa } else { xb };
        let (xc, fc) = eval(c, Some(&guess))?;
        if fc.abs() <= MATCH_TOL_PA || b - a < 1e-12 {
            return Ok((c, WastegateSolve::Matched, signals(c, &xc)));
        }
        if fc > 0.0 {
            (a, fa, xa) = (c, fc, xc);
            if side == 1 {
                fb /= 2.0;
            }
            side = 1;
        } else {
            (b, fb, xb) = (c, fc, xc);
            if side == -1 {
                fa /= 2.0;
            }
            side = -1;
        }
    }
    let c = 0.5 * (a + b);
    let (xc, _) = eval(c, Some(&xa))?;
    Ok((c, WastegateSolve::Matched, signals(c, &xc)))
}

fn stats<'a>(points: impl Iterator<Item = &'a PointCheck> + Clone, q: usize) -> QuantityStats {
    let errors = points.clone().map(|p| p.model[q] - p.measured[q]);
    let n = points.clone().count();
    let mean = if n == 0 {
        f64::NAN
    } else {
        points.clone().map(|p| p.measured[q]).sum::<f64>() / n as f64
    };
    let rmse = rms(errors);
    let (mut worst_index, mut worst_error) = (0, 0.0f64);
    for p in points {
        let e = p.model[q] - p.measured[q];
        if e.abs() > worst_error.abs() {
            (worst_index, worst_error) = (p.index, e);
        }
    }
    QuantityStats {
        rmse,
        mean,
        rmse_pct: 100.0 * rmse / mean,
        worst_index,
        worst_error,
        points: n,
    }
}

/// Runs the check over the whole map with parameters `params` and ambient pressure
/// `ambient_pressure_pa`. A point whose stationary point cannot be found fails the check (an
/// error naming it), rather than being left out of the figures.
pub fn check_engine_map(
    params: &TurboParams,
    engine: &[EnginePoint],
    ambient_pressure_pa: f64,
    opts: &FitOptions,
) -> Result<CheckReport, FitError> {
    let model = TurboModel::new(params.clone())?;
    let mut points = Vec::with_capacity(engine.len());
    for (index, p) in engine.iter().enumerate() {
        let (wastegate, solve, s) =
            check_point(&model, p, ambient_pressure_pa).map_err(|e| match e {
                FitError::Model(source) => FitError::Point { index, source },
                other => other,
            })?;
        points.push(PointCheck {
            index,
            held_out: opts.is_held_out(index),
            wastegate,
            solve,
            turbo_speed_rad_s: s.omega_t_rad_s,
            model: values(&s),
            measured: measured(p),
        });
    }
    let all = std::array::from_fn(|q| stats(points.iter(), q));
    let held_out = std::array::from_fn(|q| stats(points.iter().filter(|p| p.held_out), q));
    Ok(CheckReport {
        points,
        all,
        held_out,
    })
}
