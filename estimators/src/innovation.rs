//! What one measurement update tells a detector.

use nalgebra::{SMatrix, SVector};

use crate::linalg::{cholesky, cholesky_log_det};

/// The innovation of one measurement update: the residual between the measurement and its
/// prediction, the residual's predicted covariance, and the statistics derived from them.
///
/// Components excluded by a partial update carry a zero residual and a unit, uncorrelated
/// variance, so they add nothing to `nis`; `dof` counts only the components used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Innovation<const M: usize> {
    /// `r = y - y_pred`, in the measurement's units.
    pub residual: SVector<f64, M>,
    /// `S = cov(r)` predicted by the filter, measurement units squared.
    pub covariance: SMatrix<f64, M, M>,
    /// Normalized innovation squared `r' S^-1 r`; chi-square with `dof` degrees of freedom when
    /// the filter is consistent and no fault is present.
    pub nis: f64,
    /// Number of measurement components that took part in the update.
    pub dof: usize,
}

impl<const M: usize> Innovation<M> {
    /// Residual of component `i` divided by its predicted standard deviation (dimensionless).
    pub fn normalized(&self, i: usize) -> f64 {
        self.residual[i] / self.covariance[(i, i)].sqrt()
    }

    /// Gaussian log-likelihood `-(dof ln 2pi + ln det S + nis) / 2` of the measurement.
    ///
    /// Computed on request, not at every update: it costs a factorization and a logarithm per
    /// component, and the monitors' tests only need `nis`. Excluded components (unit variance,
    /// zero residual) add nothing. NaN if `S` is not positive definite (never after a
    /// successful update).
    pub fn log_likelihood(&self) -> f64 {
        match cholesky(&self.covariance) {
            Ok(l) => {
                -0.5 * (self.dof as f64 * (2.0 * std::f64::consts::PI).ln()
                    + cholesky_log_det(&l)
                    + self.nis)
            }
            Err(_) => f64::NAN,
        }
    }
}
