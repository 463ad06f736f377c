//! The turbo shaft: `J domega_t/dt = Tq_t - Tq_c - d omega_t - tau_0`, with `omega_t` kept within
//! `[omega_min, omega_max]` (REFERENCE §4, the generic set's 2e3 .. 2.4e4 rad/s).
//!
//! Our reading of "kept within its range": the component models see the speed clamped to the
//! range (the torques divide by it, so the minimum also keeps them finite), and the state is an
//! integrator with saturation. In the model's vector field ([`super::TurboModel::derivative`])
//! the derivative is zero at a limit when it points outward, so a stationary point can sit on a
//! limit (idle, where the exhaust cannot hold the minimum) and its Jacobian row is then zero.
//! The implicit step instead integrates the unsaturated acceleration and projects the state back
//! onto the range ([`super::TurboModel::constrain`]): with the zeroed derivative its stage
//! equations would have no solution when the speed reaches a limit within a step.

use super::ad::Scalar;

/// The shaft's constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shaft {
    /// `1 / J` (1 / (kg m^2)).
    pub inv_inertia: f64,
    /// Viscous friction (N m s/rad).
    pub friction: f64,
    /// Speed-independent loss torque (N m); the speed never reaches 0 (it is held at or above
    /// `omega_min`), so the torque's sign is fixed.
    pub friction_torque: f64,
    /// Lower speed limit (rad/s).
    pub omega_min: f64,
    /// Upper speed limit (rad/s).
    pub omega_max: f64,
}

impl Shaft {
    /// The speed the components see (rad/s).
    #[inline]
    pub fn limited<S: Scalar>(&self, omega: S) -> S {
        omega.clamp_c(self.omega_min, self.omega_max)
    }

    /// Power lost to friction at the limited speed `omega` (W).
    #[inline]
    pub fn friction_power(&self, omega: f64) -> f64 {
        let w = omega.clamp(self.omega_min, self.omega_max);
        (self.friction * w + self.friction_torque) * w
    }

    /// `domega_t/dt` (rad/s^2) at state speed `omega` from the turbine and compressor torques;
    /// `saturate` applies the limits' rule (zero where it points out of the range).
    #[inline]
    pub fn acceleration<S: Scalar>(&self, omega: S, tq_t: S, tq_c: S, saturate: bool) -> S {
        let w = self.limited(omega);
        let a = (tq_t - tq_c - w * self.friction - self.friction_torque) * self.inv_inertia;
        let v = omega.val();
        if saturate
            && ((v <= self.omega_min && a.val() < 0.0) || (v >= self.omega_max && a.val() > 0.0))
        {
            S::cst(0.0)
        } else {
            a
        }
    }
}
