//! Extended Kalman filter: the model is linearized at the current estimate each step.

use nalgebra::{SMatrix, SVector};

use crate::correction::{check_covariance, check_input, check_measurement, correct};
use crate::error::{ConfigError, FilterError};
use crate::innovation::Innovation;
use crate::linalg::{all_finite, symmetrize};
use crate::model::{ObservationModel, TransitionModel};

/// EKF for `x[k+1] = f(x[k], u[k]) + w`, `y = h(x, u) + v` with additive Gaussian noise.
/// Jacobians come from the models (analytic where they provide one, numerical otherwise).
#[derive(Debug, Clone)]
pub struct Ekf<T, O, const N: usize, const M: usize, const U: usize> {
    transition: T,
    observation: O,
    x: SVector<f64, N>,
    p: SMatrix<f64, N, N>,
    q: SMatrix<f64, N, N>,
    r: SMatrix<f64, M, M>,
}

impl<T, O, const N: usize, const M: usize, const U: usize> Ekf<T, O, N, M, U>
where
    T: TransitionModel<N, U>,
    O: ObservationModel<N, M, U>,
{
    /// Builds a filter. `p0` and `r` must be symmetric positive definite, `q` positive semidefinite.
    pub fn new(
        transition: T,
        observation: O,
        x0: SVector<f64, N>,
        p0: SMatrix<f64, N, N>,
        q: SMatrix<f64, N, N>,
        r: SMatrix<f64, M, M>,
    ) -> Result<Self, ConfigError> {
        check_covariance("P0", &p0, true)?;
        check_covariance("Q", &q, false)?;
        check_covariance("R", &r, true)?;
        if !all_finite(&x0) {
            return Err(ConfigError::InvalidParameter {
                name: "x0",
                value: f64::NAN,
                reason: "must be finite",
            });
        }
        Ok(Self {
            transition,
            observation,
            x: x0,
            p: p0,
            q,
            r,
        })
    }

    /// Current state estimate.
    pub fn state(&self) -> &SVector<f64, N> {
        &self.x
    }

    /// Current state covariance.
    pub fn covariance(&self) -> &SMatrix<f64, N, N> {
        &self.p
    }

    /// The state transition model the filter runs.
    pub fn transition_model(&self) -> &T {
        &self.transition
    }

    /// The state transition model, to change a setting of it (e.g. an assumed road surface)
    /// between steps; the estimate is kept.
    pub fn transition_model_mut(&mut self) -> &mut T {
        &mut self.transition
    }

    /// Replaces the estimate. `p` must be symmetric positive definite and `x` finite; on error
    /// nothing changes.
    pub fn reset(&mut self, x: SVector<f64, N>, p: SMatrix<f64, N, N>) -> Result<(), ConfigError> {
        check_covariance("P", &p, true)?;
        if !all_finite(&x) {
            return Err(ConfigError::InvalidParameter {
                name: "x",
                value: f64::NAN,
                reason: "must be finite",
            });
        }
        self.x = x;
        self.p = p;
        Ok(())
    }

    /// Time update with input `u`: `x = f(x, u)`, `P = F P F' + Q`. On error nothing changes.
    pub fn predict(&mut self, u: &SVector<f64, U>) -> Result<(), FilterError> {
        check_input(u)?;
        let (mut x, f) = self.transition.transition_with_jacobian(&self.x, u);
        self.transition.constrain(&mut x);
        let mut p = f * self.p * f.transpose() + self.q;
        symmetrize(&mut p);
        if !all_finite(&x) || !all_finite(&p) {
            return Err(FilterError::NonFiniteResult {
                which: "prediction",
            });
        }
        self.x = x;
        self.p = p;
        Ok(())
    }

    /// Measurement update with every component of `y`.
    pub fn update(
        &mut self,
        y: &SVector<f64, M>,
        u: &SVector<f64, U>,
    ) -> Result<Innovation<M>, FilterError> {
        self.update_subset(y, u, &[true; M])
    }

    /// Measurement update using only the components flagged in `used`. On error nothing changes.
    pub fn update_subset(
        &mut self,
        y: &SVector<f64, M>,
        u: &SVector<f64, U>,
        used: &[bool; M],
    ) -> Result<Innovation<M>, FilterError> {
        check_input(u)?;
        check_measurement(y, used)?;
        let h = self.observation.observation_jacobian(&self.x, u);
        let y_pred = self.observation.observe(&self.x, u);
        let pxy = self.p * h.transpose();
        let pyy = h * pxy + self.r;
        let mut c = correct(&self.x, &self.p, y, &y_pred, pyy, pxy, used)?;
        self.transition.constrain(&mut c.x);
        self.x = c.x;
        self.p = c.p;
        Ok(c.innovation)
    }
}
