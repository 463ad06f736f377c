//! Stationary points `f(x, u) = 0` for given inputs, for the linearization at engine-map
//! points (the paper finds them by simulating until stationary; we solve for them).
//!
//! Method: pseudo-transient continuation (Kelley and Keyes, 1998) with fully implicit Euler
//! pseudo-steps: each step solves `Y = x + dt f(Y)` by Newton's method (the SDIRK stage solver
//! of [`super::discrete`]), and `dt` grows by 4 after a step that converged and shrinks by 4
//! after one that did not. Small `dt` follows the model's own stable dynamics (what the paper
//! does by simulating until stationary), so no careful starting point is needed and the
//! iteration lands on the operating point the engine settles to; as `dt` grows to 1e12 s the
//! step becomes Newton's method on `f = 0` and converges quadratically. Solving each pseudo-step
//! to convergence, rather than taking one linearized step, is what keeps the iteration out of
//! the cycles the flow functions' kinks otherwise cause (choked/unchoked throttle, reversing
//! turbine and wastegate flows at idle); a turbo speed that settles on its limit is held there
//! by the stage solver's active set. The residual is `max_i |f_i| / s_i` (1/s) of the model's
//! (saturated) vector field with the state scales `s` of [`TurboModel::state_scales`];
//! convergence at 1e-10 1/s leaves the flows along the air path equal to about 1e-11 relative
//! (`tests/turbo_model.rs`), in 10 to 91 iterations, about 1 ms per operating point; every
//! point of a 108-point grid over speed, throttle and wastegate converges, for both parameter
//! sets.

use super::discrete::{stage, Plain, NEWTON_TOL};
use super::{TurboError, TurboInput, TurboModel, TurboState, N_STATES};

/// Convergence threshold of the scaled residual (1/s).
pub const RESIDUAL_TOL: f64 = 1e-10;
/// Most iterations.
pub const MAX_ITERATIONS: usize = 400;
/// Growth of the pseudo-time step after a converged step (and its cut after a failed one).
const GROWTH: f64 = 4.0;
/// Largest pseudo-time step (s): Newton's method up to a 1e-12 regularization.
const MAX_DT_S: f64 = 1e12;

/// A stationary point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stationary {
    /// The state.
    pub state: TurboState,
    /// Iterations used.
    pub iterations: usize,
    /// Final scaled residual `max_i |f_i| / s_i` (1/s).
    pub residual: f64,
}

impl TurboModel {
    /// A physically sensible starting state for input `u`: the intake side at ambient (the
    /// manifold at half of it), the exhaust manifold 10 % above ambient at 900 K, the exhaust
    /// system 2 % above at 800 K, the turbo at a fifth of its speed range.
    pub fn default_guess(&self, u: &TurboInput) -> TurboState {
        let (pa, ta) = (u.ambient_pressure_pa, u.ambient_temperature_k);
        let s = &self.c.shaft;
        self.state_from_pressures(
            [pa, pa, pa, 0.5 * pa, 1.1 * pa, 1.02 * pa],
            [ta, ta, ta, ta, 900.0, 800.0],
            s.omega_min + 0.2 * (s.omega_max - s.omega_min),
        )
    }

    /// Scaled residual `max_i |f_i| / s_i` (1/s); infinite if any component is not finite.
    pub fn scaled_residual(&self, f: &TurboState) -> f64 {
        let mut r = 0.0f64;
        for i in 0..N_STATES {
            let v = (f[i] / self.scales[i]).abs();
            if !v.is_finite() {
                return f64::INFINITY;
            }
            r = r.max(v);
        }
        r
    }

    /// The stationary point for input `u`, from `guess` or [`Self::default_guess`]. Fails with
    /// [`TurboError::NotConverged`] (with the residual reached) rather than return a point that
    /// is not stationary. A turbo speed stationary at one of its limits is a valid result
    /// (the shaft's derivative is zero there by the saturation rule).
    pub fn stationary_point(
        &self,
        u: &TurboInput,
        guess: Option<&TurboState>,
    ) -> Result<Stationary, TurboError> {
        self.check_input(u)?;
        let mut x = guess.copied().unwrap_or_else(|| self.default_guess(u));
        self.constrain(&mut x);
        let mut r = self.scaled_residual(&self.derivative(&x, u));
        if !r.is_finite() {
            return Err(TurboError::NonFinite {
                what: "stationary point: residual at the starting state",
            });
        }
        let d = Plain {
            model: self,
            input: u,
        };
        let mut dt = 1e-3;
        for it in 0..MAX_ITERATIONS {
            if r < RESIDUAL_TOL {
                return Ok(Stationary {
                    state: x,
                    iterations: it,
                    residual: r,
                });
            }
            match stage(&d, &x, dt, x, NEWTON_TOL) {
                Some((y, _, _)) => {
                    x = y;
                    // The model's (saturated) vector field decides stationarity.
                    r = self.scaled_residual(&self.derivative(&x, u));
                    dt = (dt * GROWTH).min(MAX_DT_S);
                }
                None => {
                    dt /= GROWTH;
                    if dt < 1e-9 {
                        return Err(TurboError::NotConverged {
                            iterations: it,
                            residual: r,
                        });
                    }
                }
            }
        }
        if r < RESIDUAL_TOL {
            return Ok(Stationary {
                state: x,
                iterations: MAX_ITERATIONS,
                residual: r,
            });
        }
        Err(TurboError::NotConverged {
            iterations: MAX_ITERATIONS,
            residual: r,
        })
    }
}
