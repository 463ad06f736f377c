//! The turbo shaft's loss torque from a measured turbo speed.
//!
//! Stationary engine-map data cannot determine the shaft's losses: the map has no turbo speed,
//! and the turbine flow fit ([`super::components::fit_turbine`]) takes whatever losses the
//! parameters hold and puts the rest of the power balance into the turbine's flow. A log with a
//! measured turbo speed at a stationary operating point can: at part load the compressor and
//! turbine powers are a few hundred watts, and the losses decide where the shaft settles. With
//! the start file's viscous friction alone (1e-6 N m s/rad, 16 W at 4,000 rad/s) and the
//! wastegate the map needs there, the model's turbo speed at the start of the TSFS09
//! throttle-step log is 10 % above the measured one (4,530 against 4,110 rad/s), and the
//! model falls 20 % above it at the log's lower throttle.
//!
//! **Which loss.** The viscous term `d omega_t` fitted to that speed (1.2e-5 N m s/rad) costs
//! 3 kW at 16,000 rad/s: the engine map's power balance then leaves the turbine too little
//! flow, the wastegate saturates closed at 153 of 344 map points and the stationary `p_im`
//! error grows from 1.8 % to 5.2 % (RMSE, all points). A loss torque independent of the speed
//! (`turbo_friction_torque_n_m`, power `tau_0 omega_t`: 0.054 N m, 220 W at the measured
//! 4,110 rad/s) matches the same speed, and the map's errors stay within 0.11 %-points of those
//! without it for `p_im`, `p_em` and the air flow; the boost, which the check matches by solving the
//! wastegate, is then out of the wastegate's reach at 80 low-load points (saturated closed;
//! `p_ic` RMSE 1.4 % against 0.25 %). So the viscous term stays the start file's and the
//! speed-independent torque is fitted. The anchor's wastegate, where the log has none, is the
//! map's for the parameters being tried ([`ShaftAnchor::wastegate`]): the loss and the opening
//! the map needs move together.
//!
//! The fit: one parameter, one equation. For a torque `tau_0`, the turbine flow is refitted to
//! the engine map with it (so the map's power balance still holds), then the model's
//! stationary point at the anchor's inputs gives a turbo speed; `tau_0` is the root of that
//! speed minus the measured one, by bisection in `log tau_0` (the speed falls monotonically as
//! the loss rises: less of the turbine's power reaches the compressor).

use super::check::check_engine_map;
use super::components::{fit_turbine, TurbineFit};
use super::map_lookup::{points_around, wastegate_from_map};
use super::{EnginePoint, FitError, FitOptions};
use crate::models::turbo::{TurboInput, TurboModel, TurboParams, X_OMEGA_T};

/// A stationary stretch of a log whose turbo speed is measured: the inputs the model needs
/// (ambient pressure excepted: the fit uses its own air-filter fit's) and the speed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShaftAnchor {
    /// Throttle (percent of the model's throttle range).
    pub throttle_pct: f64,
    /// Engine speed (rad/s).
    pub engine_speed_rad_s: f64,
    /// Intake manifold pressure measured there (Pa): where the map's wastegate is read when
    /// the log has none.
    pub p_im_pa: f64,
    /// Wastegate opening (fraction) if the log records it; `None`: the opening the model needs
    /// at the map's points around the anchor ([`wastegate_from_map`]).
    pub wastegate_frac: Option<f64>,
    /// Normalized air/fuel ratio (-).
    pub lambda: f64,
    /// Ambient temperature (K).
    pub ambient_temperature_k: f64,
    /// Measured turbo speed, mean over the stretch (rad/s).
    pub turbo_speed_rad_s: f64,
}

impl ShaftAnchor {
    /// The model's input at ambient pressure `p_amb_pa` with wastegate `wastegate_frac`.
    pub fn input(&self, p_amb_pa: f64, wastegate_frac: f64) -> TurboInput {
        TurboInput {
            throttle_pct: self.throttle_pct,
            engine_speed_rad_s: self.engine_speed_rad_s,
            wastegate_frac,
            lambda: self.lambda,
            ambient_pressure_pa: p_amb_pa,
            ambient_temperature_k: self.ambient_temperature_k,
        }
    }

    /// The anchor's wastegate for model `params`: the logged one, or the map's (the check of
    /// `params` at the `training` points on the two speed lines around the anchor).
    pub fn wastegate(
        &self,
        params: &TurboParams,
        training: &[EnginePoint],
        p_amb_pa: f64,
        opts: &FitOptions,
    ) -> Result<f64, FitError> {
        if let Some(w) = self.wastegate_frac {
            return Ok(w);
        }
        let near = points_around(training, self.engine_speed_rad_s);
        let check = check_engine_map(params, &near, p_amb_pa, opts)?;
        wastegate_from_map(&near, &check, self.engine_speed_rad_s, self.p_im_pa).ok_or(
            FitError::Solver {
                what: "shaft loss torque",
                reason: "the anchor's engine speed and p_im lie outside the map's speed lines",
            },
        )
    }
}

/// Search interval of the loss torque (N m): from a negligible loss (0.4 mW at 4,000 rad/s) to
/// 2 kW there, far beyond any turbocharger at part load. A torque the engine map's power
/// balance cannot carry (the turbine would need more than the whole exhaust flow at too many
/// points) counts as too large.
pub const TORQUE_RANGE: (f64, f64) = (1e-7, 0.5);

/// Bisection steps in `log tau_0` (the interval's 7 decades / 2^40, 1.5e-11 in `ln tau_0`: far below any figure's
/// precision, and a fixed count keeps the result deterministic).
const STEPS: usize = 40;

/// The model's stationary turbo speed at the anchor with loss torque `tau` and the turbine flow
/// refitted to `training` with it; returns the parameters, the turbine fit and the wastegate.
fn speed_with(
    training: &[EnginePoint],
    params: &TurboParams,
    anchor: &ShaftAnchor,
    p_amb_pa: f64,
    opts: &FitOptions,
    tau: f64,
) -> Result<(f64, TurboParams, TurbineFit, f64), FitError> {
    let mut p = params.clone();
    p.turbo_friction_torque_n_m = tau;
    let turbine = fit_turbine(training, &p)?;
    p.turbine_flow_k1_kg_k05_per_s_kpa = turbine.k1.value;
    p.turbine_linear_ratio = turbine.linear_ratio;
    let wastegate = anchor.wastegate(&p, training, p_amb_pa, opts)?;
    let model = TurboModel::new(p.clone())?;
    let st = model.stationary_point(&anchor.input(p_amb_pa, wastegate), None)?;
    Ok((st.state[X_OMEGA_T], p, turbine, wastegate))
}

/// What the shaft fit found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShaftFit {
    /// The fitted loss torque (N m).
    pub torque_n_m: f64,
    /// The anchor used.
    pub anchor: ShaftAnchor,
    /// The model's stationary turbo speed there with the start file's loss torque (rad/s).
    pub start_speed_rad_s: f64,
    /// With the fitted torque (rad/s).
    pub fitted_speed_rad_s: f64,
    /// The turbine flow fit with the fitted torque.
    pub turbine: TurbineFit,
    /// The wastegate opening at the anchor with the fitted torque (the logged one, or the
    /// map's).
    pub wastegate_frac: f64,
}

/// Fits the shaft's loss torque to the anchor (module docs): `params` holds every other fitted
/// value, the turbine flow is refitted with the torque and returned in the parameters.
pub fn fit_shaft_torque(
    training: &[EnginePoint],
    params: &TurboParams,
    anchor: &ShaftAnchor,
    p_amb_pa: f64,
    opts: &FitOptions,
) -> Result<(TurboParams, ShaftFit), FitError> {
    let target = anchor.turbo_speed_rad_s;
    if !(target.is_finite() && target > 0.0) {
        return Err(FitError::Solver {
            what: "shaft loss torque",
            reason: "the measured turbo speed is not a positive number",
        });
    }
    let (start_speed, ..) = speed_with(
        training,
        params,
        anchor,
        p_amb_pa,
        opts,
        params.turbo_friction_torque_n_m,
    )?;
    let (lo_d, hi_d) = TORQUE_RANGE;
    let (s_lo, ..) = speed_with(training, params, anchor, p_amb_pa, opts, lo_d)?;
    let below = |d: f64| -> Result<bool, FitError> {
        match speed_with(training, params, anchor, p_amb_pa, opts, d) {
            Ok((s, ..)) => Ok(s < target),
            Err(FitError::TooFewPoints { .. }) => Ok(true),
            Err(e) => Err(e),
        }
    };
    if !(s_lo > target) {
        return Err(FitError::Solver {
            what: "shaft loss torque",
            reason:
                "the model's turbo speed with the smallest loss is already below the measured one",
        });
    }
    if !below(hi_d)? {
        return Err(FitError::Solver {
            what: "shaft loss torque",
            reason: "the model's turbo speed with the largest loss is still above the measured one",
        });
    }
    let (mut a, mut b) = (lo_d.ln(), hi_d.ln());
    for _ in 0..STEPS {
        let m = 0.5 * (a + b);
        if below(m.exp())? {
            b = m;
        } else {
            a = m;
        }
    }
    let d = (0.5 * (a + b)).exp();
    let (speed, p, turbine, wastegate) = speed_with(training, params, anchor, p_amb_pa, opts, d)?;
    Ok((
        p,
        ShaftFit {
            torque_n_m: d,
            anchor: *anchor,
            start_speed_rad_s: start_speed,
            fitted_speed_rad_s: speed,
            turbine,
            wastegate_frac: wastegate,
        },
    ))
}
