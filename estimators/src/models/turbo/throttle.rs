//! The throttle: compressible flow from the intercooler volume into the intake manifold with
//! the tuned ratio of specific heats `k_th` (2.0 fits throttles better than 1.4, REFERENCE §4)
//! and an effective area polynomial in the plate angle.
//!
//! `th = (gain alpha + offset) pi / 180` rad for the input `alpha` in percent (VEP4:
//! `(0.86 alpha + 4)` deg), `A = a0 + a1 th + a2 th^2`, floored at 0. The flow keeps the upstream
//! temperature (an adiabatic throttle does not change the stagnation enthalpy).

use super::ad::Scalar;
use super::nozzle::Nozzle;

/// The throttle's constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Throttle {
    /// The flow function with `k_th` and the air gas constant.
    pub nozzle: Nozzle,
    /// Angle gain (rad per %).
    pub gain_rad: f64,
    /// Angle offset (rad).
    pub offset_rad: f64,
    /// `[a0, a1, a2]` (m^2, m^2/rad, m^2/rad^2).
    pub coeffs: [f64; 3],
}

impl Throttle {
    /// Effective area (m^2) at an input in percent (clamped to `0..100`).
    #[inline]
    pub fn area<S: Scalar>(&self, alpha_pct: S) -> S {
        let th = alpha_pct.clamp_c(0.0, 100.0) * self.gain_rad + self.offset_rad;
        let [a0, a1, a2] = self.coeffs;
        ((th * a2 + a1) * th + a0).max_c(0.0)
    }

    /// Signed flow (kg/s) from the intercooler volume `(p_ic, t_ic)` to the manifold
    /// `(p_im, t_im)` and the temperature it carries.
    #[inline]
    pub fn flow<S: Scalar>(&self, alpha_pct: S, p_ic: S, t_ic: S, p_im: S, t_im: S) -> (S, S) {
        self.nozzle
            .flow(self.area(alpha_pct), p_ic, t_ic, p_im, t_im)
    }
}
